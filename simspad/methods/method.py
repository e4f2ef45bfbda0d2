"""The method interface: what every reconstruction method is and returns (docs/methods.md, docs/internals.md).

A :class:`Method` reads a recording (``simspad.io.recording.Recording``) and returns a :class:`Reconstruction`:
an iterator of ``[H, W]`` float32 photon-irradiance frames (ph s⁻¹ m⁻², the unit of ``/gt/flux``) at the
requested instants, in order, plus the :class:`Bandwidth` it consumed (valid once iteration has ended).

Bandwidth accounting (docs/methods.md): each sensor read contributes its readout rate per pixel and its bits per pixel
per second; a method's bandwidth is the sum over the sensors it reads:

- raw SPAD binary frames: 1 bit per bin, at 1/bin_s;
- aggregated SPAD frames of n bins: ceil(log2(n + 1)) bits per aggregate, at the aggregate rate;
- conventional frames: ``bit_depth`` bits per frame, at the frame rate;
- events: 32 bits each, readout rate = events per pixel per second.
"""

from __future__ import annotations

import abc
import inspect
import math
from dataclasses import dataclass
from typing import ClassVar, Iterable, Iterator

import numpy as np

from simspad.errors import InputError


@dataclass(frozen=True)
class Bandwidth:
    """Data consumed by a method, per pixel.

    Attributes
    ----------
    readout_khz_per_pixel : float
        Readouts per pixel per second / 1000 (binary frames, aggregates, frames and events, summed).
    bits_per_pixel_s : float
        Bits per pixel per second, summed over the sensors read.
    """

    readout_khz_per_pixel: float
    bits_per_pixel_s: float


def aggregate_bits(n_bins: int) -> int:
    """Bits of one aggregated SPAD pixel value: ``ceil(log2(n + 1))`` (counts 0..n)."""
    return int(math.ceil(math.log2(n_bins + 1)))


class BandwidthTally:
    """Accumulates per-pixel readouts and bits over the span of sensor data a method consumed.

    ``add(readouts, bits)`` takes totals *per pixel* (already averaged over the pixel array); ``cover(t0, t1)``
    extends the time span they refer to. The rate is totals divided by the covered span.
    """

    def __init__(self) -> None:
        self.readouts = 0.0
        self.bits = 0.0
        self.t0 = math.inf
        self.t1 = -math.inf

    def add(self, readouts_per_pixel: float, bits_per_pixel: float) -> None:
        self.readouts += float(readouts_per_pixel)
        self.bits += float(bits_per_pixel)

    def cover(self, t0: float, t1: float) -> None:
        self.t0 = min(self.t0, float(t0))
        self.t1 = max(self.t1, float(t1))

    def result(self) -> Bandwidth:
        span = self.t1 - self.t0
        if not span > 0:
            return Bandwidth(0.0, 0.0)
        return Bandwidth(self.readouts / span / 1000.0, self.bits / span)


class Reconstruction:
    """Iterable of ``[H, W]`` float32 flux frames in the order of the requested instants.

    Wraps a generator; :attr:`bandwidth` is available once the iteration has finished (it raises before).
    """

    def __init__(self, frames: Iterator[np.ndarray], tally: BandwidthTally, n_frames: int):
        self._frames = frames
        self._tally = tally
        self._done = False
        self.n_frames = n_frames

    def __iter__(self) -> Iterator[np.ndarray]:
        for img in self._frames:
            yield np.asarray(img, dtype=np.float32)
        self._done = True

    def __len__(self) -> int:
        return self.n_frames

    @property
    def bandwidth(self) -> Bandwidth:
        if not self._done:
            raise RuntimeError("bandwidth is known only after the reconstruction has been iterated to its end")
        return self._tally.result()


class Method(abc.ABC):
    """Base class of a reconstruction method.

    Subclasses set the class attributes and implement :meth:`_run`, a generator yielding one ``[H, W]`` flux
    frame per requested instant while recording consumed data in ``tally``.

    Attributes
    ----------
    name : str
        Slug used on the command line (``nedi_akf``).
    label : str
        Display label with the sensors used, as in the reference paper (``"NEDI+AKF (S+E)"``).
    sensors : str
        Sensor letters: S SPAD, F conventional frames, E events (``"S+E"``).
    requires : tuple of str
        Recording groups needed (``"spad"``, ``"frames"``, ``"events"``).
    absolute_scale : bool
        Whether the output is in absolute photon irradiance (False: scored after an affine log fit).
    full_name : str
        What the abbreviation stands for, for the leaderboard's glossary.
    citation : str
        Where the method comes from (authors, venue, year), for the leaderboard's glossary.
    """

    name: str = ""
    label: str = ""
    sensors: str = ""
    requires: tuple[str, ...] = ()
    absolute_scale: bool = True
    full_name: str = ""
    citation: str = ""
    #: Parameters the constructor takes through ``**kwargs`` and hands on (the AKF's noise figures), name → default
    #: (None: derived from the recording); its named arguments are found by :meth:`parameters` itself.
    forwarded_parameters: ClassVar[dict[str, object]] = {}

    @classmethod
    def parameters(cls) -> dict[str, object]:
        """Every parameter a spec's ``[evaluation.params.<name>]`` or ``--param <name>.KEY=VALUE`` may set, with
        its default (None: derived from the recording, e.g. the aggregation rate from the SPAD's bin width)."""
        named = {n: (None if p.default is inspect.Parameter.empty else p.default)
                 for n, p in inspect.signature(cls.__init__).parameters.items()
                 if n != "self" and p.kind in (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)}
        return {**named, **cls.forwarded_parameters}

    def reconstruct(self, rec, times_s) -> Reconstruction:
        """Reconstruct flux frames at ``times_s`` (seconds, non-decreasing) from recording ``rec``."""
        times = np.asarray(times_s, dtype=np.float64).reshape(-1)
        if times.size and np.any(np.diff(times) < 0):
            raise InputError("reconstruction instants must be non-decreasing", path=getattr(rec, "path", None),
                             field="times_s")
        for kind in self.requires:
            if not rec.has(kind):
                raise InputError(f"method {self.name!r} needs the {kind!r} group, which this recording lacks",
                                 path=getattr(rec, "path", None), field=f"/{kind}")
        tally = BandwidthTally()
        return Reconstruction(self._run(rec, times, tally), tally, int(times.size))

    @abc.abstractmethod
    def _run(self, rec, times_s: np.ndarray, tally: BandwidthTally) -> Iterable[np.ndarray]:
        """Yield the reconstructions at ``times_s`` in order, adding what is read to ``tally``."""

    def __repr__(self) -> str:
        return f"<Method {self.name}: {self.label}>"
