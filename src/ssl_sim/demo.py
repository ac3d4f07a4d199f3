"""``make demo``: the default rescue scenario, headless, end to end.

The simulated robot (MuJoCo) stands in the paper's empty lab (``ssl_sim/scenarios/paper_lab.toml`` on the
shipped ``empty_lab`` scene); a person lying on the floor 1.5 m away calls for help. The very code
that would run on the real robot - ``robot.rescue.RescueBehaviour`` with the ``ssl_core`` SRP-PHAT
localizer - listens through the simulated 8-microphone cube (acoustic simulation at the MuJoCo
microphone positions), turns, drives and declares the victim found; the runner scores it against
the simulator's truth. Writes ``out/demo/results.json`` and ``out/demo/rescue.rrd`` (open it with
``rerun out/demo/rescue.rrd``).
"""
from __future__ import annotations

import sys
from pathlib import Path

from ssl_core.broken_pipe import quiet_on_broken_pipe
from ssl_sim.runner import format_summary, run_scenario
from ssl_sim.scenario import DEFAULT_SCENARIO, load_scenario


@quiet_on_broken_pipe
def main(out_dir: str = "out/demo", scenario: str = DEFAULT_SCENARIO, seed: int | None = None) -> int:
    out = Path(out_dir)
    sc = load_scenario(scenario)
    print(f"ssl-rescue demo: scenario '{sc.name}' - {sc.description}")
    print("  the rescue behaviour (robot.rescue) + SRP-PHAT localizer (ssl_core) on the simulated HAL "
          "(MuJoCo robot, simulated acoustics at its microphones)")
    rrd = out / "rescue.rrd"
    result = run_scenario(sc, seed=seed, rerun=f"save:{rrd}", out_dir=out, progress=False)
    print(format_summary(result))
    print("  what the robot did:")
    for line in result["events"]:
        if any(k in line for k in ("target", "turn", "drive", "victim_found", "recover", "explore", "all_found")):
            print("   " + line)
    print(f"wrote {out / 'results.json'} and {rrd} (view: rerun {rrd}); "
          f"more: ssl-rescue run light_rubble_three --rerun spawn")
    return 0 if result["success"] else 1


if __name__ == "__main__":
    sys.exit(main())
