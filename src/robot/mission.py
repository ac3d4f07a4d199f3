"""A mission's plumbing, apart from its decisions: the event log, the step/run loop, drive faults, and a drive
that is stopped whatever happens.

A subclass implements ``_cycle()`` (one listen/act cycle) and calls ``_emit`` for every decision and ``_finish``
to end the mission. ``step()`` stops the drive when it returns or raises; an exception is logged as an ``ERROR``
event and raised again; the audio source's own end of stream (``robot.hal.EndOfAudio``) ends the mission as
``AUDIO_ENDED``.
"""
from __future__ import annotations

import logging

from robot.events import (Decision, DriveFaultPayload, ErrorPayload, FinishPayload, Payload, RescueEvent,
                          RescueState, TimeUpPayload)
from robot.hal import Clock, DriveBase, DriveStatus, EndOfAudio

__all__ = ["Mission"]

log = logging.getLogger("robot.rescue")


class Mission:
    """``drive``, ``clock``; ``fatal_faults``: drive fault names that end the mission."""

    def __init__(self, drive: DriveBase, clock: Clock, fatal_faults: tuple[str, ...]) -> None:
        self.drive, self.clock, self.fatal_faults = drive, clock, fatal_faults
        self.state = RescueState.LISTEN
        self.events: list[RescueEvent] = []
        self.victims: list = []          # what was found, in the order declared (positions first: FinishPayload)
        self._faults_seen: tuple[str, ...] = ()
        self._step_events: list[RescueEvent] = []

    def _cycle(self) -> None:
        raise NotImplementedError

    @property
    def done(self) -> bool:
        return self.state is RescueState.DONE

    def step(self) -> list[RescueEvent]:
        """One listen/act cycle; returns its events. The drive is stopped when it returns or raises."""
        self._step_events = []
        if self.done:
            return []
        try:
            self._cycle()
        except EndOfAudio as exc:   # the source's own end of stream (any other EOFError, e.g. a model's, fails)
            self._finish(Decision.AUDIO_ENDED, f"audio source exhausted ({exc})")
        except BaseException as exc:
            failed = self._safe_stop()
            outcome = "drive stopped" if failed is None else f"stopping the drive failed too ({failed})"
            self._emit(Decision.ERROR, f"{type(exc).__name__}: {exc}; {outcome}",
                       ErrorPayload(type(exc).__name__, failed is None))
            raise
        finally:
            self._safe_stop()
        return self._step_events

    def run(self, max_time: float) -> list[RescueEvent]:
        """Step until done or ``max_time`` s of clock time have passed; returns this run's events."""
        if not max_time > 0:
            raise ValueError(f"max_time: expected > 0 s, got {max_time}")
        t_end = self.clock.now() + max_time
        out: list[RescueEvent] = []
        try:
            while not self.done and self.clock.now() < t_end:
                out += self.step()
            if not self.done:
                self._step_events = []
                self._emit(Decision.TIME_UP, f"mission time of {max_time:g} s used up", TimeUpPayload(max_time))
                out += self._step_events
        finally:
            self._safe_stop()
        return out


    def _check_faults(self, status: DriveStatus) -> bool:
        faults = tuple(status.faults)
        if faults != self._faults_seen:
            new = sorted(set(faults) - set(self._faults_seen))
            if new:
                self._emit(Decision.DRIVE_FAULT, f"drive reports fault(s) {', '.join(new)}",
                           DriveFaultPayload(list(faults)))
            self._faults_seen = faults
        fatal = sorted(set(faults) & set(self.fatal_faults))
        if fatal:
            self._finish(Decision.FAULT, f"fatal drive fault(s) {', '.join(fatal)}: stopping the mission")
            return True
        return False

    def _finish(self, decision: Decision, reason: str) -> None:
        self._safe_stop()
        self.state = RescueState.DONE
        self._emit(decision, reason, FinishPayload([v.position for v in self.victims]))

    def _safe_stop(self) -> Exception | None:
        """Stop the drive; the exception if that failed (logged, never raised)."""
        try:
            self.drive.stop()
        except Exception as exc:  # never mask the original error; the backend's own failsafe must act
            log.error("drive.stop() failed: %s", exc)
            return exc
        return None

    def _emit(self, decision: Decision, reason: str, data: Payload = Payload()) -> RescueEvent:
        ev = RescueEvent(self.clock.now(), self.state, Decision(decision), reason, data)
        self.events.append(ev)
        self._step_events.append(ev)
        log.info("%s", ev)
        return ev
