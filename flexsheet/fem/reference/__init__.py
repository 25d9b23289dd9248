"""The offline nonlinear reference of the FEM: the hyperelastic cylinder and scene solves (model, Newton, the
push along a path, the capsule finger), their cached pushes and settings, the worker processes that run them,
the fold check, and the builders of the nonlinear tables the real-time models in :mod:`flexsheet.fem` look up.
Nothing here runs in the FEM node's real-time loop."""
