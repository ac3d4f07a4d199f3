"""robot: omni-drive kinematics, the hardware abstraction layer (HAL), the
rescue behaviour and the real-hardware backends. Depends on ssl_core, never on
ssl_sim.

Robot (body) frame: origin at the base centre on the ground, +x forward,
+y left, +z up. Body twist ``(vx, vy, omega)`` in m/s, m/s, rad/s.
"""
