"""The measured-data side: logs in, identified models out.

It uses the pipeline's public names (robot descriptions, regressors, base parameters) and
adds what meeting real data needs, one module per job:

* :mod:`kindyngen.measured.logs`: reading logs (CSV, npz), cleaning and resampling them,
  zero-phase filtering and differentiation;
* :mod:`kindyngen.measured.effects`: friction, torque offset and armature as regressor
  columns and torques (the same formulas the generated code uses);
* :mod:`kindyngen.measured.estimation`: least squares (ordinary and weighted) with standard
  deviations, refusing unidentifiable excitations;
* :mod:`kindyngen.measured.consistent`: physically consistent identification (a
  semidefinite program);
* :mod:`kindyngen.measured.excitation`: excitation trajectories optimised for the condition
  number of the regressor.
"""
