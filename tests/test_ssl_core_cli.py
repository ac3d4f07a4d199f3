import json

import numpy as np
from scipy.io import wavfile

from signals import plane_wave
from ssl_core.cli import main
from ssl_core.geometry import cube8
from ssl_core.grid import direction_from_angles

FS = 16000


def _write(tmp_path, x, fs=FS):
    path = tmp_path / "rec.wav"
    wavfile.write(path, fs, np.round(x.T * 32767).astype(np.int16))
    return str(path)


def test_cli_locates_and_prints_json(tmp_path, capsys):
    u = direction_from_angles(np.deg2rad(-60), np.deg2rad(20))
    x = 0.2 * plane_wave(cube8().positions, u, np.random.default_rng(0).standard_normal(FS), FS)
    assert main([_write(tmp_path, x), "--array", "cube8", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    d = out["windows"][0]["detections"][0]
    assert abs(d["azimuth_deg"] + 60) < 1.5 and abs(d["elevation_deg"] - 20) < 1.5
    assert main([_write(tmp_path, x), "--stream"]) == 0
    assert "azimuth_deg" in capsys.readouterr().out


def test_cli_wrong_channel_count(tmp_path, capsys):
    x = np.zeros((4, FS))
    assert main([_write(tmp_path, x)]) == 2
    assert "4 channels" in capsys.readouterr().err
