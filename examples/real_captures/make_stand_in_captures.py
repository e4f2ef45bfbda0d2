"""Write a folder of stand-in captures of a spinning Siemens star, in the formats real rigs produce.

The worked example of docs/captures.md starts from a folder of captures of a SwissSPAD2-class SPAD, a Prophesee
event camera and a machine-vision frame camera. So that it runs anywhere, this script makes such a folder from a
SimSPAD simulation of the built-in ``siemens-star`` scene (96 × 96 px, 100 lx, 20 ms), written as the cameras'
own software would write it — replace it with your rig's files:

    captures/spad/cube.npy            SPAD photon cube, visionsim layout: uint8 [N, H, W/8, 1], bits packed along
    captures/spad/transforms.json     the width in NumPy's default (big) bit order; metadata ``bitpack``, ``w``, ``h``
    captures/spad/dark.npy            a dark capture (lens capped), same layout, 20 000 binary frames
    captures/events/recording.raw     Prophesee EVT 3.0; the event camera is offset by (+3, +2) px from the SPAD and
                                      its clock runs 1.5 ms late (the calibration's homography and time offset
                                      undo both)
    captures/frames/frames.tif        16-bit TIFF stack of raw DN
    captures/frames/timestamps.csv    t_start_s, t_end_s of each exposure

Usage::

    python examples/real_captures/make_stand_in_captures.py examples/real_captures/captures
"""

from __future__ import annotations

import argparse
import csv
import json
import shutil
import tempfile
from pathlib import Path

import numpy as np
import tifffile

from simspad.io.export.evt3 import Evt3Encoder, evt3_header
from simspad.io.recording import open_recording
from simspad.render.renderer import RenderSettings, render_sequence
from simspad.sensors.presets import sensor_params
from simspad.sensors.simulate import RecordingSettings, simulate_recording

SIZE = 96
EVENT_SHIFT_PX = (3, 2)        # the event camera sees the star 3 px right and 2 px down of the SPAD
EVENT_CLOCK_LATE_S = 1.5e-3    # and its timestamps run 1.5 ms late
EVENT_SENSOR = (102, 100)        # (width, height) of the event camera, px


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path, help="folder to write the captures into")
    ap.add_argument("--keep-simulation", type=Path, metavar="REC.h5",
                    help="also keep the simulated recording (with its ground truth) there, to compare with")
    args = ap.parse_args()
    out = args.out
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        render_sequence("siemens-star", None, RenderSettings(duration_s=0.02, resolution=(SIZE, SIZE), spp=4,
                                                             max_flow_px=1.0, min_rate_hz=1e3),
                        out_dir=tmp / "render", progress=False)
        sensors = {"spad": sensor_params("spad", overrides={"gate_s": 10.24e-6}),
                   "frames": sensor_params("frames", overrides={"exposure_s": 2e-3, "frame_rate_hz": 250.0}),
                   "events": sensor_params("events")}
        rec_path = simulate_recording(tmp / "render", tmp / "rec.h5",
                                      RecordingSettings(lux=100.0, sensors=sensors, seed=7), progress=False)
        with open_recording(rec_path) as rec:
            _spad(rec, out / "spad")
            _events(rec, out / "events")
            _frames(rec, out / "frames")
        if args.keep_simulation is not None:
            args.keep_simulation.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy(rec_path, args.keep_simulation)
    print(f"wrote stand-in captures into {out}")


def _spad(rec, d: Path) -> None:
    d.mkdir(parents=True, exist_ok=True)
    n, H, W = rec.spad.n_bins, rec.height, rec.width
    cube = np.lib.format.open_memmap(d / "cube.npy", mode="w+", dtype=np.uint8, shape=(n, H, (W + 7) // 8, 1))
    for i0, bits in rec.spad.iter_bits():
        cube[i0:i0 + bits.shape[0], ..., 0] = np.packbits(bits, axis=2)  # big bit order, as visionsim writes
    cube.flush()
    del cube
    (d / "transforms.json").write_text(json.dumps({"bitpack": True, "bitpack_dim": 2, "w": W, "h": H, "c": 1}))
    # a dark capture: the recording's own dark count map, drawn as 20 000 gates with the lens capped
    rng = np.random.default_rng(1)
    gate = float(rec.spad.attrs["gate_s"])
    p_dark = -np.expm1(-rec.spad.dcr_cps.astype(np.float64) * gate)
    dark = np.lib.format.open_memmap(d / "dark.npy", mode="w+", dtype=np.uint8, shape=(20_000, H, (W + 7) // 8, 1))
    for i0 in range(0, 20_000, 2000):
        dark[i0:i0 + 2000, ..., 0] = np.packbits(rng.random((2000, H, W)) < p_dark, axis=2)
    dark.flush()


def _events(rec, d: Path) -> None:
    d.mkdir(parents=True, exist_ok=True)
    dx, dy = EVENT_SHIFT_PX
    late_us = int(round(EVENT_CLOCK_LATE_S * 1e6))
    encoder = Evt3Encoder()
    with open(d / "recording.raw", "wb") as f:
        f.write(evt3_header(*EVENT_SENSOR, t_offset_us=0).replace(b"% simspad_t_offset_us 0\n", b""))
        for ev in rec.events.iter_chunks():
            f.write(encoder.encode(ev["t"] + late_us, ev["x"].astype(np.int64) + dx,
                                   ev["y"].astype(np.int64) + dy, ev["p"]).tobytes())


def _frames(rec, d: Path) -> None:
    d.mkdir(parents=True, exist_ok=True)
    with tifffile.TiffWriter(d / "frames.tif") as tw:
        for i in range(rec.frames.n_frames):
            tw.write(rec.frames.dn(i), contiguous=True)
    with open(d / "timestamps.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["t_start_s", "t_end_s"])
        for a, b in zip(rec.frames.t_start, rec.frames.t_end):
            w.writerow([repr(float(a)), repr(float(b))])


if __name__ == "__main__":
    main()
