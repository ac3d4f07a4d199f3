"""ssl_sim: the simulator (MuJoCo robot and rubble worlds, pyroomacoustics
acoustics, simulation HAL backends, scenario runner, gymnasium env).

World frame: right-handed, +z up, metres; the floor is z = 0.
"""
