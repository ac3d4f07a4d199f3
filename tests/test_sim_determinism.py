"""What the simulator renders at a pose depends on that pose only, not on what was rendered before in the
process (caches are keyed on exact geometry: a 2 mm tolerance used to reuse the first array's noise mixing
and diffuse tail for a slightly different array); and a drive is the same whichever BLAS kernel the CPU runs."""
from __future__ import annotations

import ast
import os
import subprocess
import sys

import numpy as np
import pytest
from blas_kernels import kernels as blas

from ssl_sim.acoustics import AcousticConfig, AcousticSimulator, AmbientNoise, ArrayMount, RobotPose, SensorConfig
from ssl_sim.acoustics import rir
from ssl_sim.world import Box, Room, VictimSite, World

WORLD = World(room=Room((6.0, 5.0, 3.0)), obstacles=(Box((3.0, 2.5, 0.4), (0.6, 1.2, 0.8)),),
              victims=(VictimSite((1.2, 4.0, 0.3)),))
POSE = RobotPose(4.6, 1.2, yaw=0.4)
OTHER = RobotPose(1.8, 1.5, yaw=-2.0)
BUILT = ArrayMount(build_error_m=0.0003, build_seed=5)  # another cube: capsules off by ~0.3 mm


def _sim() -> AcousticSimulator:
    # Float output and a loud ambient field: a difference far below one int16 step still shows.
    return AcousticSimulator(WORLD, AcousticConfig(ism_order=1, max_rir_s=0.3, seed=3, ambient=AmbientNoise(60.0),
                                                   sensor=SensorConfig(output="float")))


def test_rendering_does_not_depend_on_earlier_poses_or_arrays():
    rir._MIXING_CACHE.clear()
    mount = ArrayMount()
    alone = _sim().listen(mount.mic_positions_world(POSE), 0.2, t0=0.5)

    rir._MIXING_CACHE.clear()
    sim = _sim()
    for p in (OTHER, POSE):  # the other array first, at the same times: the caches now hold its geometry
        sim.listen(BUILT.mic_positions_world(p), 0.2, t0=0.5)
    later = sim.listen(mount.mic_positions_world(POSE), 0.2, t0=0.5)
    fresh_after_others = _sim().listen(mount.mic_positions_world(POSE), 0.2, t0=0.5)

    assert np.any(alone != 0)
    assert np.array_equal(alone, later)
    assert np.array_equal(alone, fresh_after_others)
    # ...and the other array really sounds different (the test would not notice a reuse otherwise).
    assert not np.array_equal(alone, _sim().listen(BUILT.mic_positions_world(POSE), 0.2, t0=0.5))


def test_averaged_poses_of_a_turning_array_are_made_rigid():
    from ssl_core.geometry import cube8
    from ssl_sim.backends import _rigid_fit

    ref = np.asarray(cube8().positions) + [1.0, 2.0, 0.27]

    def rz(a):
        return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])

    centre = ref.mean(axis=0)
    poses = [(ref - centre) @ rz(a).T + centre + [0.02 * a, 0.0, 0.0] for a in (0.0, 0.1, 0.2)]
    means = 0.5 * (np.array(poses[:-1]) + np.array(poses[1:]))  # chunk midpoints as the audio source forms them
    fitted = _rigid_fit(ref, means)

    def dist(x):
        return np.linalg.norm(x[:, None] - x[None], axis=-1)

    assert np.abs(dist(means[1]) - dist(ref)).max() > 5e-5          # the plain average is shrunk
    for f, m in zip(fitted, means):
        assert np.abs(dist(f) - dist(ref)).max() < 1e-12            # the fit has the array's exact geometry
        assert np.abs(f - m).max() < 3e-4                           # and stays where the average was


# A drive through the simulated base in a child process under the given OpenBLAS kernels: its final pose to the bit.
_DRIVE = """
import numpy as np
from ssl_sim.physics.sim_robot import SimRobot
r = SimRobot()
for vx, vy, om in np.round(np.random.default_rng(7).uniform(-0.3, 0.3, (20, 3)), 3):   # the serial link's 1 mm/s
    r.set_twist(vx, vy, om)
    r.step(0.1)
p = r.pose()
print(repr((p.x, p.y, p.yaw)))
"""


def test_a_simulated_drive_is_the_same_under_every_blas_kernel():
    """OpenBLAS rounds by the kernel its CPU selects (FMA or not); the wheels' physics turns one last bit of a
    command into another path, so the drive's arithmetic stays out of BLAS (``robot.kinematics._apply``)."""
    kernels = [k for k in ("Haswell", "Sandybridge") if blas.NEEDS[k] <= blas.cpu_flags()]
    if len(kernels) < 2:
        pytest.skip(f"this CPU runs only {kernels or 'none'} of the Haswell and Sandybridge kernels")
    poses = set()
    for k in kernels:
        p = subprocess.run([sys.executable, "-c", _DRIVE], env=dict(os.environ, OPENBLAS_CORETYPE=k),
                           capture_output=True, text=True, timeout=120)
        assert p.returncode == 0, p.stderr
        poses.add(p.stdout.strip())
    x, y, _ = ast.literal_eval(next(iter(poses)))
    assert np.hypot(x, y) > 0.05, "the base did not drive"
    assert len(poses) == 1, poses
