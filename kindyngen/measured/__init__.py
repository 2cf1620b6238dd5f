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

Every refusal of this side (bad logs, unidentifiable data, a failed solve, an impossible
request) is a :class:`MeasuredDataError`, defined here so that the command line can catch it
without importing the heavy modules at start-up.
"""


class MeasuredDataError(ValueError):
    """Data or a request the measured-data side cannot use; the message says what and where."""
