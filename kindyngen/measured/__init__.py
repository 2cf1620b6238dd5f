"""The measured-data side: logs in, identified models out.

It uses the pipeline's public names (robot descriptions, regressors, base parameters) and
adds what meeting real data needs, one module per job:

* :mod:`kindyngen.measured.log_preparing`: reading logs (CSV, npz), cleaning and resampling them,
  zero-phase filtering and differentiation;
* :mod:`kindyngen.measured.effect_columns`: friction, torque offset and armature as regressor
  columns and torques (the same formulas the generated code uses);
* :mod:`kindyngen.measured.estimation`: least squares (ordinary and weighted) with standard
  deviations, refusing unidentifiable excitations;
* :mod:`kindyngen.measured.consistent`: physically consistent identification (a
  semidefinite program);
* :mod:`kindyngen.measured.excitation`: excitation trajectories optimised for the condition
  number of the regressor;
* :mod:`kindyngen.measured.regressor_rows`: the pipeline's base regressors evaluated in batches,
  and what a description predicts along motion;
* :mod:`kindyngen.measured.identified_model`, :mod:`kindyngen.measured.identification_report`: identified models
  written back as descriptions, figures and tables;
* :mod:`kindyngen.measured.identify`: the ``identify`` command's run (in memory);
* :mod:`kindyngen.measured.log_formats`: logs read in chunks (CSV, npz, Parquet, ROS 2 and
  ROS 1 bags of JointState);
* :mod:`kindyngen.measured.log_checks`: a log checked against the robot it claims to record
  (joint limits, angles in degrees, torques, velocities and accelerations beyond physical
  bounds, time stamps not in seconds), for every command that reads logs;
* :mod:`kindyngen.measured.ls_factor`: least squares from the triangular factor, folded chunk
  by chunk and combined across logs;
* :mod:`kindyngen.measured.streaming`: the ``identify`` command's run folded into a QR factor (bounded memory), and
  fleets of logs on a process pool or Dask;
* :mod:`kindyngen.measured.discovery`, :mod:`kindyngen.measured.discrepancy`: naming the effect
  a model misses, and the ``discover`` command's run;
* :mod:`kindyngen.measured.fri_source`, :mod:`kindyngen.measured.paper_reproduction`: the
  identification paper's procedure on a simulated control interface.

Every refusal of this side (bad logs, unidentifiable data, a failed solve, an impossible
request) is a :class:`MeasuredDataError`, defined here so that the command line can catch it
without importing the heavy modules at start-up.
"""


class MeasuredDataError(ValueError):
    """Data or a request the measured-data side cannot use; the message says what and where."""
