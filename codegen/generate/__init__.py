"""Stage 3 of the pipeline: from a DiscreteScheme to a C package in memory.

- casadi_functions: the scheme's expressions translated into CasADi Functions, their
  derivatives by algorithmic differentiation, and CasADi's C code of them;
- interface: the runtime contract's facts as C text (macros, structs, prototypes, calls);
- example: the example program's target and PD gains;
- package: the templates rendered around the model code, the manifest, and the writer.
"""
