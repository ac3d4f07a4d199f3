"""Read a multichannel WAV file block by block, in bounded memory (stdlib + numpy).

``scipy.io.wavfile.read`` loads the whole file (2.3 GB for 10 min of 8-channel float64); a
memory map keeps every touched page resident. This reader parses the RIFF header itself and
reads one block of frames at a time with ``numpy.fromfile``: PCM 8/16/24/32-bit and IEEE float
32/64-bit, plain or WAVE_FORMAT_EXTENSIBLE.
"""
from __future__ import annotations

import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

_PCM, _FLOAT, _EXTENSIBLE = 1, 3, 0xFFFE


@dataclass(frozen=True)
class WavInfo:
    path: str
    fs: int               # Hz
    channels: int
    bits: int
    is_float: bool
    data_offset: int      # bytes from the file start
    n_frames: int         # samples per channel present in the file (what is read)
    header_frames: int | None = None  # samples per channel the header declares (None: not stated, e.g. RF64)

    @property
    def duration_s(self) -> float:
        return self.n_frames / self.fs

    @property
    def truncated(self) -> bool:
        """The header declares more samples than the file holds (a copy or recording cut short)."""
        return self.header_frames is not None and self.header_frames > self.n_frames

    def truncation(self) -> str:
        """One line naming the file, the length its header declares and the length present ('' if whole)."""
        if not self.truncated:
            return ""
        return (f"{self.path}: truncated: the header says {self.header_frames / self.fs:.3f} s "
                f"({self.header_frames} samples per channel), the file holds {self.duration_s:.3f} s "
                f"({self.n_frames})")


def wav_info(path: str | Path) -> WavInfo:
    """Header of a WAV file. Raises ``ValueError`` naming the file for anything it cannot read
    (``IsADirectoryError``/``PermissionError``/``FileNotFoundError`` pass through as ``OSError``)."""
    path = str(path)
    with open(path, "rb") as f:
        head = f.read(12)
        if len(head) < 12 or head[:4] not in (b"RIFF", b"RF64") or head[8:12] != b"WAVE":
            raise ValueError(f"{path}: not a WAV file (no RIFF/WAVE header)")
        fmt = None
        while True:
            chunk = f.read(8)
            if len(chunk) < 8:
                raise ValueError(f"{path}: WAV file has no data chunk" if fmt else f"{path}: WAV file has no fmt chunk")
            cid, size = chunk[:4], struct.unpack("<I", chunk[4:])[0]
            if cid == b"fmt ":
                body = f.read(size)
                if len(body) < 16:
                    raise ValueError(f"{path}: truncated WAV fmt chunk")
                tag, channels, fs, _, _, bits = struct.unpack("<HHIIHH", body[:16])
                if tag == _EXTENSIBLE and len(body) >= 26:
                    tag = struct.unpack("<H", body[24:26])[0]  # the sub-format GUID starts with the tag
                if tag not in (_PCM, _FLOAT) or (tag == _PCM and bits not in (8, 16, 24, 32)) \
                        or (tag == _FLOAT and bits not in (32, 64)):
                    raise ValueError(f"{path}: unsupported WAV encoding (format tag {tag}, {bits} bits); "
                                     "expected PCM 8/16/24/32-bit or float 32/64-bit")
                if channels < 1 or fs < 1:
                    raise ValueError(f"{path}: WAV header has {channels} channels at {fs} Hz")
                fmt = (fs, channels, bits, tag == _FLOAT)
                f.seek(size % 2, 1)
            elif cid == b"data":
                if fmt is None:
                    raise ValueError(f"{path}: WAV data chunk before the fmt chunk")
                fs, channels, bits, is_float = fmt
                offset = f.tell()
                f.seek(0, 2)
                available = f.tell() - offset
                frame_bytes = channels * bits // 8
                n = min(size, available) // frame_bytes  # a truncated file keeps its whole frames
                # 0xFFFFFFFF: length not stated in this field (RF64's ds64 chunk, streamed recordings)
                declared = None if size == 0xFFFFFFFF else size // frame_bytes
                return WavInfo(path, fs, channels, bits, is_float, offset, n, declared)
            else:
                f.seek(size + size % 2, 1)


def read_blocks(info: WavInfo, block_frames: int) -> Iterator[np.ndarray]:
    """Consecutive blocks (channels, <= block_frames) as float32 (integers scaled to [-1, 1))."""
    if block_frames < 1:
        raise ValueError(f"block_frames: expected >= 1, got {block_frames}")
    frame_bytes = info.channels * info.bits // 8
    with open(info.path, "rb") as f:
        f.seek(info.data_offset)
        left = info.n_frames
        while left > 0:
            raw = f.read(min(block_frames, left) * frame_bytes)
            n = len(raw) // frame_bytes
            if n == 0:
                return
            left -= n
            yield _to_float(raw[: n * frame_bytes], info).reshape(n, info.channels).T


def _to_float(raw: bytes, info: WavInfo) -> np.ndarray:
    """Interleaved little-endian samples -> float32, integers scaled to [-1, 1)."""
    if info.is_float:
        return np.frombuffer(raw, "<f4" if info.bits == 32 else "<f8").astype(np.float32)
    if info.bits == 8:  # 8-bit WAV is unsigned
        return (np.frombuffer(raw, np.uint8).astype(np.float32) - 128.0) / 128.0
    if info.bits == 24:
        b = np.frombuffer(raw, np.uint8).reshape(-1, 3).astype(np.int32)
        v = b[:, 0] | (b[:, 1] << 8) | (b[:, 2] << 16)
        return np.where(v >= 1 << 23, v - (1 << 24), v).astype(np.float32) / np.float32(1 << 23)
    return np.frombuffer(raw, "<i2" if info.bits == 16 else "<i4").astype(np.float32) / np.float32(2.0 ** (info.bits - 1))
