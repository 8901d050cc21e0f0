"""Peers and references: the same chain in other simulators (docs/model.md, section 10).

- mjcf: MuJoCo XML of a scene (text only);
- mujoco_runs: simulating it with MuJoCo (needs the test extra's mujoco);
- scipy_peer: the minimal-coordinate ODE, compiled, integrated by SciPy's solve_ivp.
- compiled_peers: the same compiled ODE integrated by compiled loops (numbalsoda's LSODA
  and DOP853, needs the peers extra; CVODES through CasADi).
"""
