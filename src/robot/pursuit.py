"""Per-source pursuit state: one record per map source the behaviour has gone after, and the small state machine
that moves it.

Phases::

    APPROACH --(within reach, listened)--> CLOSE --(P(find) >= p_find)--> FOUND
       |  ^                                   |
       |  +------- (moved away) --------------+
       +--(contacts, steps across a bearing exhausted)--> SET_ASIDE --(aside_s passed)--> APPROACH

A listen at a source's estimate that does not confirm it is a *miss*. Misses lower the belief that a victim is
there by Bayes' rule: a victim at the estimate is confirmed in one close listen with probability
``confirm_probability`` (fitted on the train split with the found model), so after ``k`` misses

    P(victim there | k misses) = P q^k / (P q^k + 1 - P),   q = 1 - confirm_probability.

That posterior is what the options weigh: a reflection, a machine's image or a mirror source beyond a wall loses
its draw listen by listen instead of being named and rejected by a rule.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from enum import StrEnum

from robot.config_values import need

__all__ = ["Phase", "Pursuit", "PursuitConfig", "Pursuits"]


class Phase(StrEnum):
    APPROACH = "approach"
    CLOSE = "close"
    SET_ASIDE = "set_aside"
    FOUND = "found"


@dataclass(frozen=True)
class PursuitConfig:
    """``confirm_probability``: P(one close listen confirms a victim who is there) (fitted, see the module
    docstring). ``max_contacts``: contacts while driving at one source, ``max_steps_across``: steps across its
    bearing that left it unranged, before it is set aside for ``aside_s`` s (choices: walls the robot cannot see
    otherwise draw it along them; a caller gone quiet is not triangulated by stepping to and fro)."""

    confirm_probability: float | None = None   # None: the fitted value (robot/models/found_model.json)
    max_contacts: int = 3
    max_steps_across: int = 4
    aside_s: float = 60.0

    def __post_init__(self) -> None:
        need(self, self.confirm_probability is None or 0 < self.confirm_probability < 1, "confirm_probability",
             "in (0, 1), or None for the fitted value")
        need(self, self.max_contacts >= 1, "max_contacts", "an integer >= 1")
        need(self, self.max_steps_across >= 1, "max_steps_across", "an integer >= 1")
        need(self, self.aside_s >= 0, "aside_s", ">= 0 s")


@dataclass
class Pursuit:
    """What the behaviour did about one source (``source_id``, the map's id)."""

    source_id: int
    phase: Phase = Phase.APPROACH
    contacts: int = 0
    misses: int = 0
    steps_across: int = 0
    aside_until: float = -math.inf


class Pursuits:
    """The pursuit records by source id, and their transitions."""

    def __init__(self, config: PursuitConfig = PursuitConfig(), fitted_confirm: float = 0.3) -> None:
        if config.confirm_probability is None:
            config = replace(config, confirm_probability=fitted_confirm)
        self.config = config
        self._by_id: dict[int, Pursuit] = {}

    def of(self, source_id: int) -> Pursuit:
        return self._by_id.setdefault(source_id, Pursuit(source_id))

    def available(self, source_id: int, now: float) -> bool:
        """May be pursued now: not found, not set aside (an expired set-aside goes back to APPROACH)."""
        p = self.of(source_id)
        if p.phase is Phase.SET_ASIDE and now >= p.aside_until:
            p.phase, p.contacts, p.steps_across = Phase.APPROACH, 0, 0
        return p.phase not in (Phase.FOUND, Phase.SET_ASIDE)

    def posterior(self, source_id: int, p_victim: float) -> float:
        """P(a victim at the source's estimate) after its misses (module docstring)."""
        k = self.of(source_id).misses
        q = (1.0 - self.config.confirm_probability) ** k
        return p_victim * q / (p_victim * q + 1.0 - p_victim) if 0 < p_victim < 1 else p_victim

    def missed(self, source_id: int) -> None:
        """A listen at its estimate that did not confirm it (a set-aside or found source keeps its phase)."""
        p = self.of(source_id)
        p.misses += 1
        if p.phase is Phase.APPROACH:
            p.phase = Phase.CLOSE

    def moved_away(self, source_id: int) -> None:
        p = self.of(source_id)
        if p.phase is Phase.CLOSE:
            p.phase = Phase.APPROACH

    def contact(self, source_id: int, now: float) -> bool:
        """One more contact while driving at it; True when that set it aside."""
        p = self.of(source_id)
        p.contacts += 1
        return self._aside_if(p, p.contacts >= self.config.max_contacts, now)

    def stepped_across(self, source_id: int, now: float) -> bool:
        """One more step across its bearing; True when that set it aside."""
        p = self.of(source_id)
        p.steps_across += 1
        return self._aside_if(p, p.steps_across > self.config.max_steps_across, now)

    def set_aside(self, source_id: int, now: float) -> None:
        self._aside_if(self.of(source_id), True, now)

    def found(self, source_id: int) -> None:
        self.of(source_id).phase = Phase.FOUND

    def release_all(self) -> None:
        """The grid changed (obstacles forgotten): every set-aside source may be reachable again."""
        for p in self._by_id.values():
            if p.phase is Phase.SET_ASIDE:
                p.phase, p.aside_until, p.contacts, p.steps_across = Phase.APPROACH, -math.inf, 0, 0

    def _aside_if(self, p: Pursuit, cond: bool, now: float) -> bool:
        if cond and p.phase is not Phase.FOUND:
            p.phase, p.aside_until = Phase.SET_ASIDE, now + self.config.aside_s
            return True
        return False
