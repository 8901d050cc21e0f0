"""Stage 2 of the pipeline: the symbolic model (SymPy) and the discrete schemes.

- com_model: the chain in centre-of-mass coordinates (docs/model.md, sections 1-4);
- joint_model: the chain in joint space, for "vi" and "midpoint" (sections 5, 6);
- quadrature: Gauss-Legendre nodes of the averaged spring gradient;
- schemes: one DiscreteScheme per method, the only product of this stage.
"""
