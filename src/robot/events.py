"""What the rescue behaviour decides, as typed records: the phase (``RescueState``), the decision (``Decision``), the
found cue (``FindCriterion``) and one small frozen payload per kind of decision.

A payload's ``to_dict()`` is its machine-readable form in logs and JSON (``ssl-robot --json`` lines, tools): the
field names are the keys. Units SI, angles in rad; positions in the odometry frame, bearings in the array frame.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from enum import Enum, StrEnum
from typing import Any, Self

__all__ = ["RescueState", "Decision", "FINAL", "FindCriterion", "Payload", "HeardCandidate", "HeardPayload",
           "TargetPayload", "DrivePayload", "SourcePayload", "RejectedPayload", "FoundPayload", "ContactPayload",
           "RecoverPayload", "ObstaclePayload", "DriveFaultPayload", "FinishPayload", "TimeUpPayload",
           "ErrorPayload", "RescueEvent"]


class RescueState(str, Enum):
    """Phase of the behaviour (the state an event was decided in)."""

    LISTEN = "listen"          # standing, listening, deciding
    APPROACH = "approach"      # moving toward the target
    FOUND = "found"            # a victim was just declared found
    RECOVER = "recover"        # backing off after a contact
    EXPLORE = "explore"        # moving without a target
    DONE = "done"              # finished: max victims, stuck, audio ended, fatal fault


class Decision(str, Enum):
    """What an event says; the value is its keyword in logs and ``results.json``. Its payload type in brackets."""

    HEARD = "heard"                # [HeardPayload]
    NO_SOURCE = "no_source"        # [HeardPayload]
    TARGET = "target"              # [TargetPayload]
    NO_TARGET = "no_target"        # [Payload] or [SourcePayload]
    DRIVE = "drive"                # [DrivePayload]
    EXPLORE = "explore"            # [DrivePayload]
    VICTIM_FOUND = "victim_found"  # [FoundPayload]
    REJECTED = "rejected"          # an interferer reached and still without voice [RejectedPayload]
    RECOVER = "recover"            # [ContactPayload] a contact mapped, or [RecoverPayload] the other recoveries
    OBSTACLE = "obstacle"          # a move stopped before a range return in its way [ObstaclePayload]
    DRIVE_FAULT = "drive_fault"    # [DriveFaultPayload]
    ALL_FOUND = "all_found"        # [FinishPayload]
    STUCK = "stuck"                # [FinishPayload]
    FAULT = "fault"                # [FinishPayload]
    AUDIO_ENDED = "audio_ended"    # [FinishPayload]
    TIME_UP = "time_up"            # [TimeUpPayload]
    ERROR = "error"                # [ErrorPayload]

    def __str__(self) -> str:
        return self.value


#: Decisions that end the mission.
FINAL = frozenset({Decision.ALL_FOUND, Decision.STUCK, Decision.FAULT, Decision.AUDIO_ENDED})


class FindCriterion(StrEnum):
    """The cue that added most to a find's probability (``robot.found``); the value is its keyword in
    ``results.json`` (``finds_by_criterion``)."""

    STEEP_BEARING = "steep_bearing"    # the bearing heard now points down at a mouth where the map puts her
    LEVEL_RISE = "level_rise"          # her level rose since her faintest listen
    MAP_ESTIMATE = "map_estimate"      # the map's tight estimate near the robot
    CONTACT = "contact"                # the bumper or the range sensors stopped a move at her estimate
    VOICE = "voice"                    # the map's voice evidence added most to P(find)


@dataclass(frozen=True)
class Payload:
    """A decision without data; the base of the typed payloads."""

    def to_dict(self) -> dict[str, Any]:
        """The payload as plain data, one key per field (nested records as dicts)."""
        return {f.name: _plain(getattr(self, f.name)) for f in fields(self)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Self:
        """The payload back from ``to_dict()``'s form (e.g. a JSON log line's ``data``)."""
        return cls(**d)


def _plain(v: Any) -> Any:
    if isinstance(v, Payload):
        return v.to_dict()
    if isinstance(v, list):
        return [_plain(x) for x in v]
    return v


@dataclass(frozen=True)
class HeardCandidate(Payload):
    """One bearing heard and the map source it joined (``cls``, ``state``: the source's class and state keywords)."""

    source: int
    azimuth: float
    elevation: float
    level_db: float
    voice: float                  # the beam's VAD speech-frame fraction
    voice_scan: bool              # found by the voice scan, not as an SRP-PHAT peak
    cls: str
    state: str

    def to_dict(self) -> dict[str, Any]:
        d = super().to_dict()
        d["class"] = d.pop("cls")
        d["state"] = d.pop("state")     # keeps the key order: ..., class, state
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Self:
        d = dict(d)
        d["cls"] = d.pop("class")
        return cls(**d)


@dataclass(frozen=True)
class HeardPayload(Payload):
    """A listen: detections, the candidates (sources not yet found), what was ignored (words) and the pose."""

    n_detections: int
    candidates: list[HeardCandidate]
    ignored: list[str]
    pose: list[float]             # x, y (m), yaw (rad)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Self:
        return cls(**{**d, "candidates": [HeardCandidate.from_dict(c) for c in d["candidates"]]})

    @property
    def decision(self) -> Decision:
        """HEARD with a candidate, else NO_SOURCE."""
        return Decision.HEARD if self.candidates else Decision.NO_SOURCE

    def describe(self) -> str:
        """The listen in words (angles in degrees, array frame)."""
        if not self.candidates:
            return "no source detected" if not self.n_detections else "only ignored sources: " + "; ".join(self.ignored)
        desc = "; ".join(f"#{c.source} {c.cls} az {math.degrees(c.azimuth):+.0f} deg el "
                         f"{math.degrees(c.elevation):+.0f} deg voice {c.voice:.2f}" for c in self.candidates)
        return desc + (f"; ignored: {'; '.join(self.ignored)}" if self.ignored else "")


@dataclass(frozen=True)
class TargetPayload(Payload):
    """The source chosen to approach and the plan to it."""

    source: int
    position: list[float]         # estimate x, y, z (m)
    sigma_m: float                # its horizontal 1-sigma
    victim_probability: float
    azimuth: float                # toward the estimate, array frame
    elevation: float
    path_m: float
    waypoints: list[list[float]]


@dataclass(frozen=True)
class DrivePayload(Payload):
    """A step along a plan (or an exploration, a baseline step): its length, end and legs (x, y, m)."""

    distance: float
    goal: list[float]
    legs: list[list[float]]


@dataclass(frozen=True)
class SourcePayload(Payload):
    """A decision about one map source (listen again, set aside, re-estimated)."""

    source: int


@dataclass(frozen=True)
class RejectedPayload(Payload):
    """A source never to be approached again (a machine, a reflection) and its estimate x, y, z (m)."""

    source: int
    position: list[float]


@dataclass(frozen=True)
class FoundPayload(Payload):
    """A victim declared found: the reported ``position`` (x, y) and ``height`` (m), the cue in words
    (``criterion``, with the measured values) and as a keyword (``cue``)."""

    position: tuple[float, float]
    height: float
    source: int
    criterion: str
    cue: FindCriterion
    sigma_m: float
    victim_probability: float

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Self:
        return cls(**{**d, "position": tuple(d["position"]), "cue": FindCriterion(d["cue"])})


@dataclass(frozen=True)
class ContactPayload(Payload):
    """A contact mapped (bumper, stall, slip) before backing off: the drive's flags, why (``ContactKind``
    keyword) and where the obstacle face was marked (x, y, m)."""

    bumper: bool
    stalled: bool
    kind: str
    contact: list[float]


@dataclass(frozen=True)
class RecoverPayload(Payload):
    """A recovery without a new contact: ``kind`` "clear" (``cells`` forgotten), "escape" (freed), or the
    ``ContactKind`` that blocked a back-off."""

    kind: str
    cells: int | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind} if self.cells is None else {"kind": self.kind, "cells": self.cells}


@dataclass(frozen=True)
class ObstaclePayload(Payload):
    """A move stopped before a range return in its way: the readings (m per sensor, None beyond range)."""

    ranges: list[float | None]


@dataclass(frozen=True)
class DriveFaultPayload(Payload):
    """The drive's fault names now."""

    faults: list[str]


@dataclass(frozen=True)
class FinishPayload(Payload):
    """The mission ended: the victims found (x, y, m)."""

    victims: list[tuple[float, float]]


@dataclass(frozen=True)
class TimeUpPayload(Payload):
    """The mission time (s) is used up."""

    max_time: float


@dataclass(frozen=True)
class ErrorPayload(Payload):
    """An exception ended a step: its type name and whether the drive stopped."""

    exception: str
    stopped: bool


@dataclass(frozen=True)
class RescueEvent:
    """One decision: ``time`` (s, clock), the ``state`` it was taken in, the ``decision``,
    a human-readable ``reason`` and the typed ``data`` (``to_dict()`` for its plain form)."""

    time: float
    state: RescueState
    decision: Decision
    reason: str
    data: Payload = field(default_factory=Payload)

    def __str__(self) -> str:
        return f"[{self.time:8.2f} s] {self.state.value:<8} {self.decision.value:<13} {self.reason}"
