"""Build src/ssl_sim/sounds/: real recorded speech and real non-speech sounds from Debian packages.

Reproducible: downloads the packages with ``apt-get download`` (needs ``apt-get update`` once),
extracts them with ``dpkg-deb -x``, cuts/concatenates and resamples with sox to 16 kHz mono
16-bit WAV, and writes ``src/ssl_sim/sounds/PROVENANCE`` (one tab-separated row per output file:
source package, paths inside it, license, speaker sex, content).

    python scripts/build_sound_dataset.py [--work /tmp/sounddeb]

Split: by file, speaker-disjoint for speech (no voice is in both parts). Sex: from the
package's credits where it names the speaker; else from the measured median F0 (printed).
"""
from __future__ import annotations

import argparse
import struct
import subprocess
import tempfile
from pathlib import Path

import numpy as np
from scipy.io import wavfile

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "src" / "ssl_sim" / "sounds"
FS = 16000

AST = "usr/share/asterisk/sounds"
LIN = "usr/share/games/lincity-ng/sounds"
FDS = "usr/share/sounds/freedesktop/stereo"
WES = "usr/share/games/wesnoth/1.16/data/core/sounds"
PSX = "usr/share/pocketsphinx/test/data"
MOH = "usr/share/asterisk/moh"
OSFX = "usr/share/games/openttd/baseset/opensfx/opensfx.cat"

CC_BY_SA = "CC-BY-SA-3.0"
# (split, category, name, package, [paths or opensfx:INDEX], license, sex, content, trim (start, dur) or None)
# Speech from IVR prompt sets: the largest prompts of a speaker (excluding tones/beeps/monkeys), concatenated.
SELECTION: list[tuple] = [
    # ---- speech (speaker-disjoint) -----------------------------------------------------------
    ("dev", "speech", "en_allison", "asterisk-core-sounds-en-wav", f"prompts:{AST}/en_US_f_Allison:10",
     CC_BY_SA, "female (credits: Allison Smith)", "US English IVR prompts", None),
    ("dev", "speech", "ru_ivrvoice", "asterisk-core-sounds-ru-wav", f"prompts:{AST}/ru_RU_f_IvrvoiceRU:10",
     "CC-BY-3.0", "female (credits: ivrvoice.ru, dir name ru_RU_f)", "Russian IVR prompts", None),
    ("dev", "speech", "en_an4", "pocketsphinx-testdata",
     [f"raw:{PSX}/goforward.raw", f"raw:{PSX}/numbers.raw", f"raw:{PSX}/something.raw"],
     "BSD-2-Clause", "F0", "US English commands and digits (CMU test utterances)", None),
    ("dev", "shouts", "cries_male", "wesnoth-1.16-data",
     [f"{WES}/human-die-{i}.ogg" for i in (1, 2, 3)] + [f"{WES}/human-hit-{i}.ogg" for i in (1, 2, 3, 4, 5)],
     "GPL-2+", "male (file names: human-*)", "pain cries and death screams (game voice acting)", None),
    ("test", "speech", "fr_june", "asterisk-core-sounds-fr-wav", f"prompts:{AST}/fr_CA_f_June:10",
     CC_BY_SA, "female (credits: June Wallack)", "Canadian French IVR prompts", None),
    ("test", "speech", "it_carlo", "asterisk-core-sounds-it-wav", f"prompts:{AST}/it_IT_m_Carlo:10",
     "CC-BY-3.0", "male (credits: Carlo Flora)",
     "Italian IVR prompts", None),
    ("test", "speech", "en_librivox", "pocketsphinx-testdata",
     [f"{PSX}/librivox/sense_and_sensibility_01_austen_64kb-0{k}.wav" for k in (870, 920)],
     "BSD-2-Clause (package); LibriVox recordings are public domain", "F0",
     "read English prose (LibriVox, Sense and Sensibility ch. 1)", None),
    ("test", "shouts", "cries_female_old", "wesnoth-1.16-data",
     [f"{WES}/human-female-die-{i}.ogg" for i in (1, 2, 3)] + [f"{WES}/human-female-hit-{i}.ogg" for i in (1, 2, 3)]
     + [f"{WES}/human-old-die-{i}.ogg" for i in (1, 2)],
     "GPL-2+", "female and elderly male (file names)", "pain cries and death screams (game voice acting)", None),
    # ---- machinery: motors, pumps, generators, saws, hammers ---------------------------------
    ("dev", "machinery", "mining_machinery", "openttd-opensfx", ["opensfx:11"], "opensfx", "", "mining machinery (elevator)", None),
    ("dev", "machinery", "sawmill", "openttd-opensfx", ["opensfx:40"], "opensfx", "", "circular saw", None),
    ("dev", "machinery", "industry_high", "lincity-ng-data", [f"{LIN}/IndustryHigh1.wav"], "GPL-2+", "", "heavy industry", None),
    ("dev", "machinery", "power_coal", "lincity-ng-data", [f"{LIN}/PowerCoalFull.wav"], "GPL-2+", "", "coal power station", None),
    ("test", "machinery", "jackhammer", "openttd-opensfx", ["opensfx:33"], "opensfx", "", "air hammer", None),
    ("test", "machinery", "chainsaw", "openttd-opensfx", ["opensfx:56"], "opensfx", "", "chainsaw", None),
    ("test", "machinery", "industry_light", "lincity-ng-data", [f"{LIN}/IndustryLight1.wav"], "GPL-2+", "", "light industry", None),
    ("test", "machinery", "ore_mine", "lincity-ng-data", [f"{LIN}/OreMine1.wav"], "GPL-2+", "", "ore mine machinery", None),
    ("test", "machinery", "mill", "lincity-ng-data", [f"{LIN}/Mill1.wav"], "GPL-2+", "", "mill", None),
    # ---- engines: vehicles, aircraft ---------------------------------------------------------
    ("dev", "engine", "truck_start", "openttd-opensfx", ["opensfx:25"], "opensfx", "", "old truck/bus engine start, pull away", None),
    ("dev", "engine", "propeller_plane", "openttd-opensfx", ["opensfx:8"], "opensfx", "", "propeller plane start", None),
    ("test", "engine", "helicopter", "openttd-opensfx", ["opensfx:24"], "opensfx", "", "helicopter", None),
    ("test", "engine", "modern_bus", "openttd-opensfx", ["opensfx:27"], "opensfx", "", "bus approaches and leaves", None),
    ("test", "engine", "old_bus", "openttd-opensfx", ["opensfx:28"], "opensfx", "", "old bus start", None),
    # ---- alarms, beeps, horns, bells ----------------------------------------------------------
    ("dev", "alarm", "alarm_clock", "sound-theme-freedesktop", [f"{FDS}/alarm-clock-elapsed.oga"], CC_BY_SA, "", "alarm clock", (0.0, 3.5)),
    ("dev", "alarm", "level_crossing", "openttd-opensfx", ["opensfx:14"], "opensfx", "", "railway level-crossing bell", None),
    ("dev", "alarm", "factory_whistle", "openttd-opensfx", ["opensfx:3"], "opensfx", "", "factory whistle", None),
    ("test", "alarm", "phone_ring", "sound-theme-freedesktop",
     [f"{FDS}/phone-incoming-call.oga", f"{FDS}/phone-incoming-call.oga"], "GPL-2+", "", "phone ringing (twice)", None),
    ("test", "alarm", "busy_tone", "sound-theme-freedesktop", [f"{FDS}/phone-outgoing-busy.oga"], "GPL-2+", "", "telephone busy tone", None),
    ("test", "alarm", "morse_beeps", "openttd-opensfx", ["opensfx:22", "opensfx:22"], "opensfx", "", "morse beeps (twice)", None),
    ("test", "alarm", "ship_horn", "openttd-opensfx", ["opensfx:6"], "opensfx", "", "ship horn", None),
    # ---- knocking, tapping, hammering --------------------------------------------------------
    ("dev", "knock", "blacksmith", "lincity-ng-data", [f"{LIN}/Blacksmith1.wav"], "GPL-2+", "", "hammer on anvil", None),
    ("test", "knock", "smithy", "openttd-opensfx", ["opensfx:39"], "opensfx", "", "hammering in a smithy", None),
    ("test", "knock", "mace_club_fist", "wesnoth-1.16-data", [f"{WES}/mace.ogg", f"{WES}/club.ogg", f"{WES}/fist.ogg",
     f"{WES}/mace.ogg", f"{WES}/club.ogg"], "GPL-2+", "", "blunt impacts", None),
    # ---- rubble, crashes, falling debris ----------------------------------------------------
    ("dev", "rubble", "rumble", "wesnoth-1.16-data", [f"{WES}/rumble.ogg"], "GPL-2+", "", "rumbling earth", (0.0, 4.0)),
    ("dev", "rubble", "crash", "openttd-opensfx", ["opensfx:17", "opensfx:16"], "opensfx", "", "crash, dumpster clatter", None),
    ("test", "rubble", "cave_in", "wesnoth-1.16-data", [f"{WES}/cave-in.ogg"], "GPL-2+", "", "cave-in, falling rocks", None),
    ("test", "rubble", "big_crash_tree", "openttd-opensfx", ["opensfx:19", "opensfx:54"], "opensfx", "", "big crash, tree crashing", None),
    # ---- wind, fans, steam, hum ----------------------------------------------------------------
    ("dev", "wind_hum", "wind", "openttd-opensfx", ["opensfx:52"], "opensfx", "", "wind", None),
    ("test", "wind_hum", "heavy_wind", "openttd-opensfx", ["opensfx:57"], "opensfx", "", "heavy wind", None),
    ("test", "wind_hum", "electric_sparking_steam", "openttd-opensfx", ["opensfx:10", "opensfx:13"], "opensfx", "",
     "electric sparking (Jacob's ladder hum), steam", None),
    # ---- music (instrumental hold music) -----------------------------------------------------
    ("dev", "music", "cold_day", "asterisk-moh-opsound-wav", [f"{MOH}/macroform-cold_day.wav"], CC_BY_SA, "", "instrumental music", (60.0, 4.0)),
    ("test", "music", "morning_coffee", "asterisk-moh-opsound-wav", [f"{MOH}/manolo_camp-morning_coffee.wav"], CC_BY_SA, "",
     "instrumental music", (20.0, 4.0)),
    ("test", "music", "system", "asterisk-moh-opsound-wav", [f"{MOH}/reno_project-system.wav"], CC_BY_SA, "", "instrumental music", (90.0, 4.0)),
]
EXCLUDE_PROMPTS = ("beep", "tone", "monkeys", "silence", "weasels")


def _opensfx_name(cat: Path, index: int) -> str:
    """Entry ``index``'s description in OpenSFX's .cat archive (title, author, license)."""
    d = cat.read_bytes()
    off = struct.unpack("<I", d[8 * index: 8 * index + 4])[0] & 0x7FFFFFFF
    return d[off + 1: off + 1 + d[off]].rstrip(b"\0").decode("latin1")


def _opensfx(cat: Path, index: int, tmp: Path) -> Path:
    """Entry ``index`` of OpenSFX's .cat archive (offset/size table, then name-prefixed RIFF data)."""
    d = cat.read_bytes()
    off, size = struct.unpack("<II", d[8 * index: 8 * index + 8])
    off &= 0x7FFFFFFF
    ln = d[off]
    out = tmp / f"opensfx_{index}.wav"
    out.write_bytes(d[off + 1 + ln: off + size])
    return out


def _prompts(folder: Path, seconds: float) -> list[Path]:
    """The largest prompt WAVs of a speaker of at most 5 s each (no tones/beeps), adding up to at most
    ``seconds`` (8 kHz 16-bit files: 16 000 bytes per s)."""
    dur = {p: (p.stat().st_size - 44) / 16000.0 for p in folder.glob("*.wav")
           if not any(x in p.name for x in EXCLUDE_PROMPTS)}
    chosen, total = [], 0.0
    for p in sorted((p for p in dur if dur[p] <= 5.0), key=lambda p: (-dur[p], p.name)):
        if total + dur[p] <= seconds:
            chosen.append(p)
            total += dur[p]
    return chosen


def median_f0(x: np.ndarray, fs: int = FS) -> float:
    """Median autocorrelation pitch (Hz, 60-400) of the loud 40 ms frames: a sex cue for the provenance."""
    n = int(0.04 * fs)
    frames = x[: len(x) // n * n].reshape(-1, n).astype(float)
    e = (frames**2).sum(1)
    frames = frames[e > 0.1 * e.max()]
    ac = np.fft.irfft(np.abs(np.fft.rfft(frames * np.hanning(n), 2 * n)) ** 2)[:, :n]
    lo, hi = fs // 400, fs // 60
    lag = lo + np.argmax(ac[:, lo:hi], axis=1)
    ok = ac[np.arange(len(ac)), lag] > 0.4 * ac[:, 0]
    return float(np.median(fs / lag[ok])) if ok.any() else float("nan")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", default="/tmp/sounddeb", help="download/extract folder")
    args = ap.parse_args()
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    packages = sorted({row[3] for row in SELECTION})
    for pkg in packages:
        if not (work / "x" / pkg).exists():
            if not list(work.glob(f"{pkg}_*.deb")):
                subprocess.run(["apt-get", "download", pkg], cwd=work, check=True)
            deb = sorted(work.glob(f"{pkg}_*.deb"))[-1]
            subprocess.run(["dpkg-deb", "-x", str(deb), str(work / "x" / pkg)], check=True)
    rows = ["split\tcategory\tfile\tseconds\tsource_package\tpaths_in_package\tlicense\tspeaker_sex\tcontent"]
    with tempfile.TemporaryDirectory() as td:
        tmp = Path(td)
        for split, cat, name, pkg, srcs, lic, sex, content, trim in SELECTION:
            base = work / "x" / pkg
            if isinstance(srcs, str) and srcs.startswith("prompts:"):
                _, folder, secs = srcs.split(":")
                srcs = [str(p.relative_to(base)) for p in _prompts(base / folder, float(secs))]
            inputs, shown = [], []
            if lic == "opensfx":  # each OpenSFX entry names its own license
                lic = " / ".join(dict.fromkeys(
                    _opensfx_name(base / OSFX, int(x.split(":")[1])).split("License: ")[1].split(". ")[0].rstrip(".")
                    for x in srcs))
            for s in srcs:
                if s.startswith("opensfx:"):
                    inputs += [str(_opensfx(base / OSFX, int(s.split(":")[1]), tmp))]
                    shown.append(f"{OSFX}#{s.split(':')[1]}")
                elif s.startswith("raw:"):
                    inputs += ["-t", "raw", "-r", "16000", "-e", "signed", "-b", "16", "-c", "1", str(base / s[4:])]
                    shown.append(s[4:])
                else:
                    inputs.append(str(base / s))
                    shown.append(s)
            # each input to 16 kHz mono first (sox concatenation needs equal rates/channels)
            parts = []
            i = 0
            k = 0
            while i < len(inputs):
                if inputs[i] == "-t":
                    spec, i = inputs[i: i + 11], i + 11
                else:
                    spec, i = [inputs[i]], i + 1
                part = tmp / f"{name}_{k}.wav"
                k += 1
                subprocess.run(["sox", "-D", *spec, "-r", str(FS), "-c", "1", "-b", "16", str(part), "remix", "-", "rate", "-v",
                                str(FS)], check=True)
                parts.append(str(part))
            out = OUT / split / cat / f"{name}.wav"
            out.parent.mkdir(parents=True, exist_ok=True)
            effects = ["trim", str(trim[0]), str(trim[1])] if trim else []
            subprocess.run(["sox", "-D", *parts, str(out), *effects, "norm", "-1"], check=True)
            fs, x = wavfile.read(out)
            if sex == "F0":
                f0 = median_f0(x)
                sex = f"{'male' if f0 < 165 else 'female'} (median F0 {f0:.0f} Hz, measured)"
            print(f"{split:4s} {cat:10s} {name:24s} {len(x) / fs:5.1f} s  {sex}")
            rows.append("\t".join([split, cat, str(out.relative_to(OUT)), f"{len(x) / fs:.2f}", pkg, "; ".join(shown),
                                   lic, sex or "-", content]))
    (OUT / "PROVENANCE").write_text(
        "# Real recordings for the voice-activity detector (scripts/build_sound_dataset.py writes this file).\n"
        "# All from Debian bookworm packages (main); licenses as in each package's copyright file.\n"
        "# 16 kHz mono 16-bit WAV (sox, no dither: reproducible), peak-normalised to -1 dBFS; IVR prompts are 8 kHz\n# recordings upsampled.\n"
        + "\n".join(rows) + "\n")


if __name__ == "__main__":
    main()
