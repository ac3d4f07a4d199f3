"""An AudioSource that watches the microphones while passing audio on (``ssl_core.health``).

Every block read is fed to a ``MicHealth`` monitor; when the confirmed faults change, each new fault is
logged as a warning (the robot log), each cleared one as info, the localizer's excluded channels are
updated (``Localizer.exclude_channels``: a faulty microphone's pairs leave the SRP sum automatically), a
``device_slip`` makes the source re-measure its devices' alignment (``AudioSource.resync``), and
``on_change(time, new, cleared)`` is called (the CLI prints, the simulator logs to rerun).
"""
from __future__ import annotations

import logging
from typing import Callable, Protocol, Sequence

from ssl_core.health import Fault, HealthReport, MicHealth

from robot.hal import AudioBlock, AudioSource

log = logging.getLogger(__name__)


class ChannelExcluder(Protocol):
    def exclude_channels(self, channels: Sequence[int]) -> None: ...


FaultCallback = Callable[[float, Sequence[Fault], Sequence[Fault]], None]


class MonitoredAudio(AudioSource):
    """``source`` with ``monitor`` watching it; ``localizer`` (optional) gets the excluded channels."""

    def __init__(self, source: AudioSource, monitor: MicHealth, localizer: ChannelExcluder | None = None,
                 on_change: FaultCallback | None = None) -> None:
        if monitor.geometry.n_mics != source.n_channels:
            raise ValueError(f"monitor: array '{monitor.geometry.name}' has {monitor.geometry.n_mics} mics, "
                             f"the audio source {source.n_channels} channels")
        if monitor.config.fs != source.sample_rate:
            raise ValueError(f"monitor: HealthConfig.fs = {monitor.config.fs} Hz, the audio source delivers "
                             f"{source.sample_rate} Hz")
        self.source, self.monitor, self.localizer, self.on_change = source, monitor, localizer, on_change
        self._faults: dict[tuple, Fault] = {}
        self._excluded: tuple[int, ...] = ()
        self.history: list[tuple[float, str, Fault]] = []  # (stream time s, "new"/"cleared", fault)

    @property
    def sample_rate(self) -> int:
        return self.source.sample_rate

    @property
    def n_channels(self) -> int:
        return self.source.n_channels

    @property
    def report(self) -> HealthReport:
        return self.monitor.report

    def read(self, n_samples: int) -> AudioBlock:
        block = self.source.read(n_samples)
        report = self.monitor.update(block.samples)
        if report is not None:
            self._apply(report, block.timestamp + block.samples.shape[1] / block.sample_rate)
        return block

    def _apply(self, report: HealthReport, time: float) -> None:
        now = {(f.kind, f.channels): f for f in report.faults}
        new = [f for k, f in now.items() if k not in self._faults]
        cleared = [f for k, f in self._faults.items() if k not in now]
        self._faults = now
        for f in new:
            log.warning("microphone fault at %.1f s: %s", time, f)
            self.history.append((time, "new", f))
        for f in cleared:
            log.info("microphone fault cleared at %.1f s: %s", time, f)
            self.history.append((time, "cleared", f))
        if report.excluded != self._excluded:
            self._excluded = report.excluded
            if self.localizer is not None:
                self.localizer.exclude_channels(report.excluded)
                if report.excluded:
                    log.warning("localizing without microphone(s) %s", list(report.excluded))
                else:
                    log.info("localizing with all microphones again")
        slips = [f.value for f in new if f.kind == "device_slip"]
        if slips:  # two-device capture: re-measure the offset now, near the slip seen, not at the next track
            self.source.resync(slips[0])
        if (new or cleared) and self.on_change is not None:
            self.on_change(time, new, cleared)

    def flush(self) -> None:
        self.source.flush()

    def resync(self, slip_samples: float | None = None) -> None:
        self.source.resync(slip_samples)

    def close(self) -> None:
        self.source.close()
