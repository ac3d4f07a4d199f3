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


def test_cli_bad_inputs_are_one_line_errors_with_exit_code_2(tmp_path, capsys):
    import os

    x = 0.2 * plane_wave(cube8().positions, direction_from_angles(0.3, 0.1),
                         np.random.default_rng(1).standard_normal(FS), FS)
    good = _write(tmp_path, x)
    unreadable = tmp_path / "locked.wav"
    unreadable.write_bytes(open(good, "rb").read())
    os.chmod(unreadable, 0)
    not_wav = tmp_path / "notes.wav"
    not_wav.write_text("hello")
    cases = [([str(tmp_path)], "is a directory"), ([str(tmp_path / "missing.wav")], "no such file"),
             ([str(not_wav)], "not a WAV"), ([good, "--array", str(tmp_path)], "--array"),
             ([good, "--sources", "0"], "--sources"), ([good, "--resolution", "0.05"], "MB"),
             ([good, "--band", "3000", "300"], "--band 3000 300"),
             ([good, "--sources", "2", "--min-separation", "2"], "--min-separation 2")]
    if os.access(unreadable, os.R_OK):  # running as root: permissions do not apply
        cases = [c for c in cases if "locked" not in c[0][0]]
    else:
        cases.append(([str(unreadable)], "permission denied"))
    for argv, needle in cases:
        assert main(argv) == 2, argv
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and err.startswith("ssl-locate: ") and needle in err, (argv, err)
        if argv[0] != good:
            assert argv[0] in err  # names the file


def test_cli_no_source_says_so_and_fails_only_when_asked(tmp_path, capsys):
    path = _write(tmp_path, np.zeros((8, FS)))
    assert main([path]) == 0
    assert "no source" in capsys.readouterr().err
    assert main([path, "--require-source"]) == 1
    assert "no source" in capsys.readouterr().err


def test_cli_reads_24_bit_and_float_wav_in_blocks(tmp_path, capsys):
    from ssl_core.wav_blocks import read_blocks, wav_info

    u = direction_from_angles(np.deg2rad(120), np.deg2rad(-10))
    x = 0.2 * plane_wave(cube8().positions, u, np.random.default_rng(2).standard_normal(2 * FS), FS)
    f32 = tmp_path / "f32.wav"
    wavfile.write(f32, FS, x.T.astype(np.float32))
    pcm24 = tmp_path / "pcm24.wav"  # scipy cannot write 24-bit: pack the bytes by hand
    v = np.round(x.T * (2**23 - 1)).astype(np.int32).reshape(-1)
    raw = np.stack([v & 0xFF, (v >> 8) & 0xFF, (v >> 16) & 0xFF], axis=1).astype(np.uint8).tobytes()
    import struct
    fmt = struct.pack("<HHIIHH", 1, 8, FS, FS * 8 * 3, 8 * 3, 24)
    pcm24.write_bytes(b"RIFF" + struct.pack("<I", 4 + 8 + len(fmt) + 8 + len(raw)) + b"WAVE" + b"fmt "
                      + struct.pack("<I", len(fmt)) + fmt + b"data" + struct.pack("<I", len(raw)) + raw)
    for path in (f32, pcm24):
        got = np.concatenate(list(read_blocks(wav_info(path), 5000)), axis=1)
        assert got.shape == x.shape and np.max(np.abs(got - x)) < 1e-6
        assert main([str(path), "--json"]) == 0
        d = json.loads(capsys.readouterr().out)["windows"][0]["detections"][0]
        assert abs(d["azimuth_deg"] - 120) < 1.5 and abs(d["elevation_deg"] + 10) < 1.5


def test_cli_names_a_truncated_wav_and_processes_what_is_there(tmp_path, capsys):
    """A 2 s recording cut to its first second (the header still says 2 s): a warning with both lengths, and the
    same answer as a whole file holding that first second."""
    u = direction_from_angles(np.deg2rad(40), np.deg2rad(-10))
    x = 0.2 * plane_wave(cube8().positions, u, np.random.default_rng(3).standard_normal(2 * FS), FS)
    whole = tmp_path / "whole.wav"
    wavfile.write(whole, FS, np.round(x.T * 32767).astype(np.int16))
    data = whole.read_bytes()
    cut = tmp_path / "cut.wav"
    cut.write_bytes(data[:44 + FS * 8 * 2])          # header (2 s) + the first second of frames
    first = tmp_path / "first.wav"
    wavfile.write(first, FS, np.round(x[:, :FS].T * 32767).astype(np.int16))

    assert main([str(cut), "--stream", "--json"]) == 0
    got = capsys.readouterr()
    warning = got.err.strip().splitlines()
    assert len(warning) == 1 and "warning" in warning[0] and str(cut) in warning[0], got.err
    assert "2.000 s (32000 samples per channel)" in warning[0] and "1.000 s (16000)" in warning[0]
    assert main([str(first), "--stream", "--json"]) == 0
    ref = capsys.readouterr()
    # --stream --json: one JSON line per window, the same windows for the cut file as for its first second
    a = [json.loads(line) for line in got.out.splitlines()]
    b = [json.loads(line) for line in ref.out.splitlines()]
    assert ref.err == "" and a == b and len(a) > 0
