"""Views: what a person looks at (matplotlib, optional extra `plot`).

- plots: `chaingen plot`, joint angles and errors of trajectory files;
- animate: `chaingen animate`, the chain and its springs to scale (GIF, MP4);
- order_plot: the log-log figure of a time-step study;
- readme_figures: the README's figures;
- run_summary: `simulate`'s text summary of a run (its maxima say over which samples);
- figure: the Agg figure and the all-or-nothing PNG writer they share.
"""
