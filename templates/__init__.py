"""Jinja2 templates of the generated C package (data only)."""
