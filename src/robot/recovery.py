"""Getting free: what the robot does after a contact, and when the learned obstacles close every way.

* **After a contact** (bumper, stall, gyro-detected slip) the obstacle is mapped where the bumper ring met it, the
  floor behind a bumper contact is taken as heard (the coverage's shadow: walls are learned only by touch), and the
  robot backs off along the way it came.
* **Clearing** (as in navigation stacks' clearing recovery): when no way is left on the learned grid, the cells
  marked by a single contact are forgotten. Odometry drifts, and contacts placed by drift close corridors that
  exist.
* **Escape**: a short move in eight directions (the four axes first, then the diagonals: wedged between two debris
  pieces the robot may pass between them), standing before each so the last push's friction is released.
  A failed push leaves the robot pressed against what it met and the next direction stalls on that friction;
  standing first lets it go. When a whole round stalled and none pressed the bumper the robot is not walled in but
  wedged, a wheel against a piece of debris: it turns in place (half the 120 deg wheel spacing: each wheel meets
  the debris at another angle) before the next round. "Stuck" only when every round failed.
"""
from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass
from typing import Callable

from robot.config_values import need
from robot.coverage import ListeningCoverage
from robot.events import ContactPayload, Decision, Payload, RecoverPayload
from robot.motion import Blocked, ContactKind, Motion
from robot.occupancy import OccupancyGrid

__all__ = ["RecoveryConfig", "Recovery"]

_WHAT = {ContactKind.BUMPER: "bumper pressed", ContactKind.STALL: "wheels stalled",
         ContactKind.SLIP: "wheels slipping (gyro)"}


@dataclass(frozen=True)
class RecoveryConfig:
    """``settle_s``: standing before each escape move (s); ``wedged_turn_deg``: turn in place after a round of
    stalls without a bumper press; ``escape_rounds``: rounds of eight moves before "stuck"."""

    settle_s: float = 0.3
    wedged_turn_deg: float = 45.0
    escape_rounds: int = 2

    def __post_init__(self) -> None:
        need(self, self.settle_s >= 0, "settle_s", ">= 0 s")
        need(self, 0 < self.wedged_turn_deg < 180, "wedged_turn_deg", "in (0, 180) degrees")
        need(self, self.escape_rounds >= 1, "escape_rounds", "an integer >= 1")


class Recovery:
    """Recoveries on ``motion`` that map what they meet into ``grid`` (and ``coverage``), count every contact in
    ``contacts`` and report through ``emit(decision, reason, payload)``; ``stuck(reason)`` ends the mission."""

    def __init__(self, motion: Motion, grid: OccupancyGrid, coverage: ListeningCoverage, contacts: Counter,
                 emit: Callable[[Decision, str, Payload], object], stuck: Callable[[str], None],
                 config: RecoveryConfig = RecoveryConfig()) -> None:
        self.motion, self.grid, self.coverage, self.contacts = motion, grid, coverage, contacts
        self.emit, self.stuck, self.config = emit, stuck, config

    def after_contact(self, b: Blocked, when: str) -> None:
        """Map the contact ``b``, back off; escape if backing off is blocked too."""
        pose = self.motion.odometry.pose
        contact = self.grid.mark_contact(pose, b.heading, b.kind)
        if b.kind is ContactKind.BUMPER:
            self.coverage.shadow(contact, b.heading, self.grid.config.contact_width_m)
        what = _WHAT[b.kind]
        self.emit(Decision.RECOVER, f"{what} {when}: obstacle mapped at ({contact[0]:.2f}, {contact[1]:.2f}), "
                                    f"back off {self.motion.config.backoff_m:g} m and replan",
                  ContactPayload(b.status.bumper, b.status.stalled, b.kind, contact.tolist()))
        if not self.back_off(b.heading, what):
            self.escape(f"backing off blocked after: {what}")

    def back_off(self, heading_world: float, why: str) -> bool:
        try:
            self.motion.back_off(heading_world)
            return True
        except Blocked as b:
            self.contacts[b.kind] += 1
            if b.kind is not ContactKind.FAULT:
                self.grid.mark_contact(self.motion.odometry.pose, b.heading, b.kind)
                self.emit(Decision.RECOVER, f"backing off blocked ({b.kind}) after: {why}", RecoverPayload(b.kind))
            return False

    def clear(self) -> int:
        """Forget the cells marked by a single contact; how many."""
        n = self.grid.forget()
        if n:
            self.emit(Decision.RECOVER, f"the learned obstacles close every way: {n} cell(s) marked by a single "
                                        "contact forgotten (clearing recovery)", RecoverPayload("clear", n))
        return n

    def escape(self, why: str) -> None:
        """Short moves in eight directions, in rounds (module docstring); ``stuck`` when all fail."""
        cfg = self.config
        kinds: list[ContactKind] = []
        turned = False
        for attempt in range(cfg.escape_rounds):
            if attempt and ContactKind.BUMPER not in kinds:
                turned = True
                try:
                    self.motion.turn(math.radians(cfg.wedged_turn_deg))
                except Blocked as b:
                    self.contacts[b.kind] += 1
                    if b.kind is ContactKind.FAULT:
                        return
            yaw = float(self.motion.odometry.pose[2])
            kinds, tried = [], []
            for k in (0, 2, 4, 6, 1, 3, 5, 7):
                heading = k * math.pi / 4
                self.motion.stand(cfg.settle_s)
                try:
                    self.motion.translate(heading, self.motion.config.backoff_m, self.motion.config.recover_speed,
                                          arm_bumper_on_release=True)
                    self.emit(Decision.RECOVER, f"{why}; freed by moving {math.degrees(heading):.0f} deg (robot "
                                                f"frame){' after turning in place' if turned else ''}",
                              RecoverPayload("escape"))
                    return
                except Blocked as b:
                    self.contacts[b.kind] += 1
                    if b.kind is ContactKind.FAULT:
                        return
                    kinds.append(b.kind)
                    tried.append(f"{math.degrees(heading):.0f} deg: {b.kind}")
                    self.grid.mark_contact(self.motion.odometry.pose, yaw + heading, b.kind)
        self.stuck(f"{why}; a move in each of eight directions was blocked, {cfg.escape_rounds} times "
                   f"(last round: {', '.join(tried)})")
