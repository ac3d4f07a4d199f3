"""robot: omni-drive kinematics, the hardware abstraction layer (HAL), the
rescue behaviour and the real-hardware backends. Depends on ssl_core, never on
ssl_sim.

Modules: ``kinematics`` (omni-drive IK/FK), ``hal`` (interfaces), ``odometry``
(dead reckoning), ``voice`` (beam + voice-likeness), ``rescue`` (the behaviour:
``RescueBehaviour``, ``RescueConfig``), ``replay`` (WAV source, dry-run drive),
``hardware`` (serial drive, USB audio capture), ``cli`` (``ssl-robot``).

Robot (body) frame: origin at the base centre on the ground, +x forward,
+y left, +z up. Body twist ``(vx, vy, omega)`` in m/s, m/s, rad/s.
"""
