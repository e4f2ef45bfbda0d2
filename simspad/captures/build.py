"""``simspad import``: build a recording (docs/format.md section 3) from real captures and a calibration file.

Steps, each sensor streamed in chunks (memory flat in the capture's length):

1. The calibration (:func:`simspad.io.captures.calibration.load_calibration`) names the captures; each is opened
   and its size checked against the calibration's.
2. **Time.** A sensor's timestamps plus its ``time_offset_s`` are on the rig's common clock. The recording starts
   at ``[capture] t_start_s`` (default: the earliest first sample of any sensor) and lasts ``duration_s``
   (default: up to the latest sample); recording time 0 is that start (root attribute ``capture_t0_s`` keeps it
   on the common clock). Event timestamps are whole µs: offsets are rounded to the µs. Samples outside the span
   are dropped: binary frames and conventional frames whose window starts outside it, events outside it.
3. **Geometry** (:mod:`simspad.captures.geometry`): each sensor is mapped onto the reference grid by its
   homography; the valid region (``/calibration/valid_mask``) is where every sensor sees the grid, within an
   optional mask image.
4. **Frame response**: from the calibration, or (``[frames.emva]``) measured from an EMVA 1288 capture set by
   :func:`simspad.analysis.emva.photon_transfer` (gain, temporal dark noise, saturation capacity; black level =
   the dark stack's mean), the calibration's own values winning.
5. **Dark counts**: ``dcr_cps`` (uniform), ``dcr_map`` (a ``.npy``, or an ``.npz``'s ``dcr_cps``, on the SPAD's
   pixels) or ``dark_capture`` (a capture with the lens capped, same format and options as the SPAD's: the ML rate
   ``−ln(1 − k/n)/gate_s`` of k ones in n gates, k = n counted as n − ½; its format from its suffix, its
   packing options the SPAD's); else the ``dcr_cps`` an ``.npz`` carries.
6. The recording is written through :class:`~simspad.io.recording.RecordingWriter` (a temporary sibling, renamed
   when complete); it has no ``/gt``: ``simspad evaluate`` scores it without ground truth.
"""

from __future__ import annotations

import itertools
import json
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from simspad import __version__
from simspad.analysis.emva import photon_transfer
from simspad.captures.geometry import SensorWarp, pose_homography
from simspad.errors import InputError
from simspad.io.captures import events as event_files
from simspad.io.captures import spad as spad_files
from simspad.io.captures.calibration import SPAD_FORMATS, Calibration, SensorCalibration, load_calibration
from simspad.io.captures.frames import FrameStack, read_timestamps
from simspad.io.compression import SPAD_COMPRESSIONS
from simspad.io.provenance import created_utc
from simspad.io.recording import RecordingWriter

#: HDF5 chunk rows of the event columns (as the simulator writes them).
EVENT_CHUNK_ROWS = 1 << 16
#: Binary frames per HDF5 chunk of ``/spad/bits``.
SPAD_CHUNK_BINS = 256


@dataclass
class ImportSummary:
    """What :func:`import_captures` wrote."""

    path: Path
    width: int
    height: int
    duration_s: float
    n_bins: int = 0
    n_frames: int = 0
    n_events: int = 0
    n_events_dropped: int = 0
    valid_fraction: float = 1.0


class _Spad:
    def __init__(self, cal: SensorCalibration):
        o = cal.options
        self.cal = cal
        self.cube = spad_files.open_cube(cal.format, cal.path, width=cal.width, height=cal.height,
                                         bit_order=o["bit_order"], bitpack_dim=o["bitpack_dim"],
                                         frame_header_bytes=o["frame_header_bytes"])
        c = self.cube
        if (cal.width and cal.width != c.width) or (cal.height and cal.height != c.height):
            raise InputError(f"the capture holds {c.width} × {c.height} pixels, the calibration says "
                             f"{cal.width} × {cal.height}", path=cal.path, field="spad.width")
        self.bin_s = o["bin_s"] if o["bin_s"] is not None else c.bin_s
        if self.bin_s is None:
            raise InputError("the capture states no bin width: give bin_s", path=cal.path, field="spad.bin_s")
        self.gate_s = o["gate_s"] if o["gate_s"] is not None else (c.gate_s if c.gate_s is not None else self.bin_s)
        if c.n_bins == 0:
            raise InputError("the capture holds no binary frames", path=cal.path, field="spad.path")
        self.shape = (c.height, c.width)

    def t_start(self, i0: int, i1: int) -> np.ndarray:
        """Start of bins ``i0:i1`` on the sensor's clock, s."""
        if self.cube.t_start_s is not None and self.cal.options["t_start_s"] is None:
            return self.cube.t_start_s[i0:i1]
        t0 = self.cal.options["t_start_s"] or 0.0
        return t0 + np.arange(i0, i1) * self.bin_s

    def span(self) -> tuple[float, float]:
        n = self.cube.n_bins
        off = self.cal.time_offset_s
        return float(self.t_start(0, 1)[0]) + off, float(self.t_start(n - 1, n)[0]) + self.bin_s + off

    def dcr_map(self) -> np.ndarray:
        o, path = self.cal.options, self.cal.path
        if o["dcr_cps"] is not None:
            return np.full(self.shape, o["dcr_cps"], np.float64)
        if o["dcr_map"] is not None:
            return _read_map(o["dcr_map"], self.shape)
        if o["dark_capture"] is not None:
            dark_fmt = SPAD_FORMATS.get(o["dark_capture"].suffix.lower(), self.cal.format)
            dark = spad_files.open_cube(dark_fmt, o["dark_capture"], width=self.cube.width,
                                        height=self.cube.height, bit_order=o["bit_order"],
                                        bitpack_dim=o["bitpack_dim"], frame_header_bytes=o["frame_header_bytes"])
            counts = np.zeros(self.shape, np.int64)
            for _, bits in spad_files.iter_bits(dark):
                counts += bits.sum(axis=0, dtype=np.int64)
            n = dark.n_bins
            k = np.where(counts >= n, n - 0.5, counts)
            return -np.log1p(-k / n) / self.gate_s
        if self.cube.dcr_cps is not None:
            if self.cube.dcr_cps.shape != self.shape:
                raise InputError(f"shape {self.cube.dcr_cps.shape}, expected {self.shape}", path=path,
                                 field="dcr_cps")
            return self.cube.dcr_cps
        raise InputError("no dark count rate: give dcr_cps, dcr_map or dark_capture", path=path,
                         field="spad.dcr_cps")


def _read_map(path: Path, shape) -> np.ndarray:
    try:
        if path.suffix.lower() == ".npz":
            with np.load(path, allow_pickle=False) as z:
                if "dcr_cps" not in z.files:
                    raise InputError("the archive has no 'dcr_cps' array", path=path, field="dcr_cps")
                m = np.asarray(z["dcr_cps"], np.float64)
        else:
            m = np.asarray(np.load(path, allow_pickle=False), np.float64)
    except (OSError, ValueError) as exc:
        raise InputError(f"unreadable dark count map ({exc})", path=path) from None
    if m.shape != tuple(shape):
        raise InputError(f"shape {m.shape}, expected the SPAD's {tuple(shape)}", path=path, field="dcr_map")
    if not np.all(np.isfinite(m) & (m >= 0)):
        raise InputError("dark count rates must be finite and ≥ 0", path=path, field="dcr_map")
    return m


def _emva_response(cal: SensorCalibration) -> dict:
    """Gain, read noise, full well and black level measured from the calibration's EMVA 1288 capture set (flat
    fields at increasing illumination and a dark stack): :func:`simspad.analysis.emva.photon_transfer`; the black
    level is the dark stack's mean. Only the fields the calibration does not give are returned."""
    emva = cal.options["emva"]

    def stack(path: Path) -> np.ndarray:
        fmt = "png" if path.is_dir() else "tiff"
        frames = np.stack(list(FrameStack(fmt, path).frames())).astype(np.float64)
        if frames.shape[0] < 2:
            raise InputError("an EMVA 1288 stack needs at least 2 frames", path=path, field="frames.emva")
        return frames

    dark = stack(emva["dark"])
    try:
        pt = photon_transfer([stack(p) for p in emva["flats"]], dark)
    except ValueError as exc:  # too few levels in the linear range, …: the capture set, not a bug
        raise InputError(f"EMVA 1288 analysis failed: {exc}", path=cal.path, field="frames.emva.flats") from None
    measured = {"gain_dn_per_e": pt.gain_dn_per_e, "read_noise_e": pt.read_noise_e, "full_well_e": pt.saturation_e,
                "black_level_dn": float(dark.mean()), "dsnu_e": pt.dsnu_e, "prnu": pt.prnu}
    if not (np.isfinite(pt.gain_dn_per_e) and pt.gain_dn_per_e > 0):
        raise InputError(f"EMVA 1288 analysis gave a gain of {pt.gain_dn_per_e} DN/e- (flat fields not brighter "
                         "than the dark stack?)", path=cal.path, field="frames.emva.flats")
    return {k: v for k, v in measured.items() if k not in cal.attrs}


class _Frames:
    def __init__(self, cal: SensorCalibration):
        if cal.options.get("emva") is not None:
            cal = replace(cal, attrs={**cal.attrs, **_emva_response(cal)})
        self.cal = cal
        self.stack = FrameStack(cal.format, cal.path)
        H, W = self.stack.shape
        if (cal.width and cal.width != W) or (cal.height and cal.height != H):
            raise InputError(f"the frames are {W} × {H} pixels, the calibration says {cal.width} × {cal.height}",
                             path=cal.path, field="frames.width")
        self.shape = (H, W)
        o = cal.options
        n = self.stack.n_frames
        if o["timestamps"] is not None:
            self.ts, self.te = read_timestamps(o["timestamps"], n)
        else:
            self.ts = o["t_start_s"] + np.arange(n) / o["frame_rate_hz"]
            self.te = self.ts + o["exposure_s"]
        self.ts = self.ts + cal.time_offset_s
        self.te = self.te + cal.time_offset_s
        self.dn_max = 2 ** cal.attrs["bit_depth"] - 1

    def span(self) -> tuple[float, float]:
        return float(self.ts[0]), float(self.te[-1])


class _Events:
    def __init__(self, cal: SensorCalibration, chunk: int):
        self.cal = cal
        size = event_files.SIZES[cal.format](cal.path)
        w, h = cal.width or (size[0] if size else None), cal.height or (size[1] if size else None)
        if size and ((cal.width and cal.width != size[0]) or (cal.height and cal.height != size[1])):
            raise InputError(f"the file states {size[0]} × {size[1]} pixels, the calibration {cal.width} × "
                             f"{cal.height}", path=cal.path, field="events.width")
        if w is None or h is None:
            raise InputError("the file states no sensor size: give width and height", path=cal.path,
                             field="events.width")
        self.shape = (int(h), int(w))
        self.offset_us = int(round(cal.time_offset_s * 1e6))
        stream = event_files.read_events(cal.format, cal.path, chunk)
        first = next((c for c in stream if c["t"].size), None)
        self.first_t_us = None if first is None else int(first["t"][0]) + self.offset_us
        self.chunks = itertools.chain([first] if first is not None else [], stream)


def _valid_mask(cal: Calibration, warps: list[SensorWarp]) -> np.ndarray:
    valid = np.ones((cal.height, cal.width), bool)
    for w in warps:
        valid &= w.sees
    if cal.valid_mask is not None:
        path = cal.valid_mask
        try:
            if path.suffix.lower() == ".npy":
                m = np.load(path, allow_pickle=False)
            else:
                import imageio.v3 as iio  # deferred: only a mask image needs it
                m = iio.imread(path)
        except (OSError, ValueError) as exc:
            raise InputError(f"unreadable mask ({exc})", path=path, field="reference.valid_mask") from None
        m = np.asarray(m)
        if m.ndim == 3:
            m = m[..., 0]
        if m.shape != valid.shape:
            raise InputError(f"shape {m.shape}, expected the reference grid's {valid.shape}", path=path,
                             field="reference.valid_mask")
        valid &= m > 0
    return valid


def import_captures(calibration_path, out, *, progress: bool = True, chunk_events: int = event_files.CHUNK_EVENTS,
                    compression: str = "zstd") -> ImportSummary:
    """Build the recording ``out`` from the captures a calibration file describes.

    Parameters
    ----------
    calibration_path : path
        The calibration TOML (docs/format.md section 9).
    out : path
        The recording to write (``.h5``); written under a temporary name and renamed when complete.
    progress : bool
        Progress bars on stderr, one per sensor.
    chunk_events : int
        Events decoded per step.
    compression : str
        Storage filter of ``/spad/bits`` (``"zstd"``, ``"gzip"``, ``"none"``).

    Raises
    ------
    InputError
        A bad calibration or capture, naming the file and the field.
    """
    cal = load_calibration(calibration_path)
    out = Path(out)
    spad = _Spad(cal.sensors["spad"]) if "spad" in cal.sensors else None
    frames = _Frames(cal.sensors["frames"]) if "frames" in cal.sensors else None
    events = _Events(cal.sensors["events"], chunk_events) if "events" in cal.sensors else None
    sensors = [s for s in (spad, frames, events) if s is not None]
    width = cal.width or sensors[0].shape[1]
    height = cal.height or sensors[0].shape[0]
    cal = replace(cal, width=width, height=height)
    warps = {}
    for s in sensors:
        pose = s.cal.options.get("pose")
        if pose is not None:
            s.cal = replace(s.cal, homography=pose_homography(pose["K"], pose["R"], pose["t"], pose["d"],
                                                              cal.reference_intrinsics))
        if s.cal.homography is None and s.shape != (height, width):
            raise InputError(f"the sensor is {s.shape[1]} × {s.shape[0]} pixels, the reference grid {width} × "
                             f"{height}: give a homography onto the grid", path=cal.path,
                             field=f"{s.cal.kind}.homography")
        warps[s.cal.kind] = SensorWarp(s.cal.homography, s.shape, (height, width))
    valid = _valid_mask(cal, list(warps.values()))
    if not valid.any():
        raise InputError("no reference pixel is seen by every sensor: check the homographies", path=cal.path,
                         field="reference")

    # The span on the common clock: [t0, t1)
    starts = ([spad.span()[0]] if spad else []) + ([frames.span()[0]] if frames else []) + \
        ([events.first_t_us * 1e-6] if events and events.first_t_us is not None else [])
    if not starts and cal.t_start_s is None:
        raise InputError("the captures hold no samples", path=cal.path, field="capture")
    t0 = cal.t_start_s if cal.t_start_s is not None else min(starts)
    t1 = t0 + cal.duration_s if cal.duration_s is not None else None
    t0_us = int(round(t0 * 1e6))
    summary = ImportSummary(out, width, height, 0.0, valid_fraction=float(valid.mean()))
    root = {"dataset": "captures", "sequence": cal.name, "scene": cal.scene, "trajectory": "", "lux": cal.lux,
            "width": width, "height": height, "speed_factor": 1.0, "simspad_version": __version__,
            "created_utc": created_utc(), "ground_truth": False, "capture_t0_s": t0, "t_start_s": 0.0,
            "time_origin_s": 0.0, "calibration": cal.text, "calibration_file": cal.path.name,
            "spec": json.dumps({"evaluation": {"rate_hz": cal.rate_hz}, "source": "simspad import"}),
            "duration_s": cal.duration_s or 0.0, "gt_rate_hz": cal.rate_hz}
    if cal.star is not None:
        s = cal.star
        root["star_region"] = json.dumps({"center_x_px": s.center_x_px, "center_y_px": s.center_y_px,
                                          "radius_px": s.radius_px, "n_cycles": s.n_cycles,
                                          "contrast": s.contrast})
    ends = []
    with RecordingWriter(out, root) as w:
        w.write_dataset("calibration/valid_mask", valid.astype(np.uint8))
        for kind, warp in warps.items():
            w.write_dataset(f"calibration/homography_{kind}", warp.h)
        if spad is not None:
            n, end = _write_spad(w, spad, warps["spad"], valid, t0, t1, compression, progress)
            summary.n_bins = n
            ends.append(end)
        if frames is not None:
            n, end = _write_frames(w, frames, warps["frames"], valid, t0, t1, progress)
            summary.n_frames = n
            ends.append(end)
        if events is not None:
            n, dropped, end, ms_counts = _write_events(w, events, warps["events"], valid, t0_us, t1, progress)
            summary.n_events, summary.n_events_dropped = n, dropped
            if end is not None:
                ends.append(end)
        duration = cal.duration_s if cal.duration_s is not None else (max(ends) if ends else 0.0)
        if not duration > 0:
            raise InputError("no sample of any sensor lies in the recording's span", path=cal.path,
                             field="capture.t_start_s")
        if events is not None:
            _write_ms_index(w, ms_counts, duration)
        w.set_attrs("/", duration_s=duration, t_end_s=duration,
                    sensors=",".join(k for k in ("spad", "frames", "events") if k in cal.sensors))
        summary.duration_s = duration
    return summary


def _sensor_attrs(cal: SensorCalibration, extra: dict) -> dict:
    return {**cal.attrs, **extra, "time_offset_s": cal.time_offset_s, "source_file": cal.path.name,
            "source_format": cal.format, "model": "real capture (simspad import)"}


def _write_spad(w, spad: _Spad, warp: SensorWarp, valid, t0, t1, compression, progress) -> tuple[int, float]:
    H, W = warp.ref_shape
    n_all = spad.cube.n_bins
    w.write_dataset("spad/dcr_cps", warp.nearest(spad.dcr_map(), valid).astype(np.float32),
                    attrs={"units": "counts s-1"})
    bits_ds = w.append_dataset("spad/bits", (H, (W + 7) // 8), np.uint8, chunk_rows=SPAD_CHUNK_BINS,
                               attrs={"bit_order": "little", "axis_packed": "width"},
                               storage=SPAD_COMPRESSIONS[compression])
    t_ds = w.append_dataset("spad/t_start", (), np.float64, chunk_rows=4096)
    n, last_end = 0, 0.0
    bar = tqdm(total=n_all, unit="bin", desc="spad", disable=not progress, leave=False)
    with bar:
        for i0, bits in spad_files.iter_bits(spad.cube):
            i1 = i0 + bits.shape[0]
            # recording time: sensor clock + offset − start
            t = (spad.t_start(i0, i1) + spad.cal.time_offset_s) - t0
            keep = (t >= -1e-12) & ((t + spad.bin_s <= (t1 - t0) + 1e-12) if t1 is not None else True)
            if keep.any():
                sel = bits[keep]
                bits_ds.append(np.packbits(warp.nearest(sel, valid), axis=2, bitorder="little"))
                t_ds.append(t[keep])
                n += int(keep.sum())
                last_end = float(t[keep][-1]) + spad.bin_s
            bar.update(bits.shape[0])
    if n == 0:
        raise InputError("no binary frame lies in the recording's span", path=spad.cal.path, field="spad.t_start_s")
    w.set_attrs("spad", **_sensor_attrs(spad.cal, {"bin_s": spad.bin_s, "gate_s": spad.gate_s, "n_bins": n,
                                                   "frame_rate_hz": 1.0 / spad.bin_s, "gate_auto": False,
                                                   "t0": 0.0, "compression": compression}))
    return n, last_end


def _write_frames(w, frames: _Frames, warp: SensorWarp, valid, t0, t1, progress) -> tuple[int, float]:
    H, W = warp.ref_shape
    ts, te = frames.ts - t0, frames.te - t0
    keep = (ts >= -1e-12) & ((te <= (t1 - t0) + 1e-12) if t1 is not None else True)
    if not keep.any():
        raise InputError("no frame's exposure lies in the recording's span", path=frames.cal.path,
                         field="frames.t_start_s")
    dn_ds = w.append_dataset("frames/dn", (H, W), np.uint16, chunk_rows=1)
    bar = tqdm(total=int(keep.sum()), unit="frame", desc="frames", disable=not progress, leave=False)
    with bar:
        for k, img in enumerate(frames.stack.frames()):
            if not keep[k]:
                continue
            if warp.identity:
                out = warp.nearest(img, valid)
            else:
                out = np.clip(np.rint(warp.bilinear(img, valid)), 0, frames.dn_max).astype(np.uint16)
            dn_ds.append(out[None])
            bar.update(1)
    w.write_dataset("frames/t_start", ts[keep])
    w.write_dataset("frames/t_end", te[keep])
    exposure = te[keep] - ts[keep]
    period = float(np.median(np.diff(ts[keep]))) if keep.sum() > 1 else float(exposure[0])
    w.set_attrs("frames", **_sensor_attrs(frames.cal, {
        "n_frames": int(keep.sum()), "frame_period_s": period, "frame_rate_hz": 1.0 / period,
        "exposure_s": float(np.median(exposure)), "exposure_mode": "fixed", "dn_max": frames.dn_max,
        "shutter": "global", "rgb": False, "rolling_shutter_line_s": 0.0}))
    return int(keep.sum()), float(te[keep][-1])


def _write_events(w, events: _Events, warp: SensorWarp, valid, t0_us, t1, progress):
    cal = events.cal
    Hs, Ws = events.shape
    t1_us = None if t1 is None else int(round(t1 * 1e6))
    cols = {k: w.append_dataset(f"events/{k}", (), dt, chunk_rows=EVENT_CHUNK_ROWS)
            for k, dt in (("t", np.int64), ("x", np.uint16), ("y", np.uint16), ("p", np.uint8))}
    n = dropped = read = 0
    last_t = None
    ms_counts = np.zeros(0, np.int64)
    bar = tqdm(unit="ev", unit_scale=True, desc="events", disable=not progress, leave=False)
    with bar:
        for ev in events.chunks:
            t = ev["t"] + events.offset_us
            if t.size == 0:
                continue
            if (last_t is not None and t[0] < last_t) or (t.size > 1 and bool((np.diff(t) < 0).any())):
                bad = 0 if last_t is not None and t[0] < last_t else int(np.argmax(np.diff(t) < 0)) + 1
                raise InputError(f"timestamps go back in time at event {read + bad} ({int(t[bad])} µs)",
                                 path=cal.path, field="events.t")
            x, y = ev["x"], ev["y"]
            bad = (x < 0) | (x >= Ws) | (y < 0) | (y >= Hs)
            if bad.any():
                k = int(np.argmax(bad))
                raise InputError(f"event {read + k} at (x {int(x[k])}, y {int(y[k])}) lies outside the "
                                 f"{Ws} × {Hs} sensor", path=cal.path, field="events.x" if x[k] >= Ws or x[k] < 0
                                 else "events.y")
            last_t = int(t[-1])
            read += t.size
            rt = t - t0_us
            xr, yr, keep = warp.events(x, y, valid)
            keep = keep & (rt >= 0) & ((rt < t1_us - t0_us) if t1_us is not None else True)
            dropped += int(t.size - keep.sum())
            if keep.any():
                rt = rt[keep]
                cols["t"].append(rt)
                cols["x"].append(xr[keep])
                cols["y"].append(yr[keep])
                cols["p"].append(ev["p"][keep])
                ms = rt // 1000
                if ms[-1] >= ms_counts.size:
                    ms_counts = np.concatenate([ms_counts, np.zeros(int(ms[-1]) + 1 - ms_counts.size,
                                                                        np.int64)])
                ms_counts += np.bincount(ms, minlength=ms_counts.size)
                n += int(keep.sum())
                last = int(rt[-1])
            bar.update(t.size)
    w.set_attrs("events", **_sensor_attrs(cal, {"n_events": n, "timestamp_unit": "us",
                                                "polarity": "1 ON, 0 OFF", "n_events_dropped": dropped}))
    return n, dropped, (last + 1) * 1e-6 if n else None, ms_counts


def _write_ms_index(w, counts: np.ndarray, duration_s: float) -> None:
    """``/events/ms_to_idx`` from the events per millisecond: entry k is the number of events before k ms."""
    n_ms = int(math.ceil(round(duration_s * 1e3, 6))) + 1
    padded = np.zeros(n_ms, np.int64)
    m = min(counts.size, n_ms - 1)
    padded[1:m + 1] = counts[:m]
    w.write_dataset("events/ms_to_idx", np.cumsum(padded).astype(np.uint64), attrs={"origin_us": 0})
    w.set_attrs("events", ms_to_idx_origin_us=0)
