"""Optimal control and MPC over any fixed-base arm KinDynGen reads (docs/reference/control.md):

- :mod:`.robot`: ``prepare(model)`` derives the robot's fd, fd_derivatives, tau and fk_hom once
  into a cache keyed by content; :class:`~.robot.Limits` and their readers;
- :mod:`.native`: the shooting stages in C per robot, horizon, interval and integrator;
- :mod:`.reach`, :mod:`.time_optimal`: transcriptions (multiple shooting on fd, the inverse-
  dynamics form, minimum time) solved by IPOPT (the native library's exact derivatives) or fatrop;
- :mod:`.mpc`, :mod:`.closed_loop`: the tracking MPC (Gauss-Newton SQP, DAQP) and its two-rate
  loop with disturbance estimate, exact-penalty limits, time budget and fallback;
- :mod:`.plan_command`: ``kindyngen plan``.
"""
