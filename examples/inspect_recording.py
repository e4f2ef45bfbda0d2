"""Inspect a recording: ground truth beside what each sensor recorded at one instant.

Run on any recording, e.g. one of the mini dataset::

    python examples/inspect_recording.py output/mini/recordings/fan/fan_100lx.h5 --out fan_100lx.png

Panels: the sharp ground-truth irradiance; one SPAD binary frame; n SPAD bins around the instant inverted with
the ML estimator (docs/sensors.md) in the same units as the ground truth; the conventional frame whose exposure holds
the instant (DN, black level removed); 1 ms of events (ON red, OFF blue). The printout compares the SPAD
estimate with the ground truth averaged over the same bins, against the estimator's predicted spread, over the
pixels where that prediction applies: hot pixels, zero estimates and nearly empty or full pixels are excluded and
their numbers printed.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from simspad.io.recording import open_recording  # noqa: E402
from simspad.errors import SimSpadError  # noqa: E402
from simspad.methods.spad_response import estimate_flux, log_flux_variance  # noqa: E402
from simspad.physics.radiometry import detection_area_m2  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("recording")
    parser.add_argument("--time", type=float, default=None, help="instant in s (default: middle ground truth)")
    parser.add_argument("--bins", type=int, default=244, help="SPAD bins to aggregate (244 ≈ 0.4 kHz)")
    parser.add_argument("--out", default="recording.png")
    args = parser.parse_args()

    with open_recording(args.recording) as rec:
        gt_t = rec.gt.t
        i_gt = len(gt_t) // 2 if args.time is None else int(np.argmin(np.abs(gt_t - args.time)))
        t = float(gt_t[i_gt])
        gt = rec.gt.flux(i_gt)
        panels = [("ground truth (ph s⁻¹ m⁻²)", gt, "gray")]

        if rec.has("spad"):
            a = rec.spad.attrs
            t_start = rec.spad.t_start
            k = int(np.clip(np.searchsorted(t_start, t) - args.bins // 2, 0, max(len(t_start) - args.bins, 0)))
            n = min(args.bins, len(t_start) - k)
            counts = rec.spad.counts(k, k + n)
            q_m2 = detection_area_m2(a["pixel_pitch_m"], a["fill_factor"], a["qe"])
            flux = estimate_flux(counts, n, q_m2, a["gate_s"], rec.spad.dcr_cps)
            panels.append((f"SPAD bit plane {k}", rec.spad.bits(k, k + 1)[0], "gray"))
            panels.append((f"SPAD {n} bins, ML estimate", flux, "gray"))
            # Ground truth averaged over the aggregate's span, to compare like with like.
            sel = (gt_t >= t_start[k]) & (gt_t <= t_start[k + n - 1] + a["bin_s"])
            ref = rec.gt.flux(np.flatnonzero(sel)).mean(axis=0) if sel.any() else gt
            # The self-check compares like with like: pixels where the estimate has a logarithm and the predicted
            # spread (a normal law in ln Φ) applies. Excluded, and counted:
            # - hot pixels: their dark counts swamp the photons, the DCR subtraction leaves ≈ 0 and ln 0 is not an
            #   error of the estimator. The recording keeps the DCR map and the two populations' medians; a pixel
            #   is hot above their geometric mean (each population crosses it with probability < 0.2 %);
            # - pixels whose estimate is 0 (no detections beyond the expected dark counts): ln 0 again;
            # - pixels with ≤ 10 or ≥ n − 10 ones, where the Cramér–Rao normal approximation does not hold.
            dcr = rec.spad.dcr_cps
            hot = dcr > np.sqrt(a["dcr_median_cps"] * a["hot_pixel_dcr_cps"])
            zero = ~hot & (flux <= 0)
            window = (counts > 10) & (counts < n - 10)
            ok = window & ~hot & ~zero
            rel = np.log(flux[ok] / ref[ok])
            pred = np.sqrt(log_flux_variance(ref[ok], n, q_m2, a["gate_s"], dcr[ok]))
            print(f"SPAD gate {a['gate_s'] * 1e6:.3g} µs, {n} bins: log error mean {rel.mean():+.4f}, "
                  f"rms {rel.std():.4f} vs predicted {np.sqrt(np.mean(pred ** 2)):.4f} ({ok.sum()} pixels; "
                  f"excluded {hot.sum()} hot, {zero.sum()} with estimate 0, "
                  f"{(~window & ~hot & ~zero).sum()} outside 10 < counts < n − 10)")

        if rec.has("frames"):
            fa = rec.frames.attrs
            j = int(np.clip(np.searchsorted(rec.frames.t_start, t, side="right") - 1, 0, rec.frames.n_frames - 1))
            dn = rec.frames.dn(j).astype(np.float64) - fa["black_level_dn"]
            panels.append((f"frame {j} (DN − black, {fa['exposure_s'] * 1e3:.3g} ms)", dn, "gray"))

        if rec.has("events"):
            ev = rec.events.window(t - 0.5e-3, t + 0.5e-3)
            img = np.zeros((rec.height, rec.width))
            np.add.at(img, (ev["y"], ev["x"]), np.where(ev["p"] == 1, 1.0, -1.0))
            lim = max(1.0, np.abs(img).max())
            panels.append((f"events ±0.5 ms ({len(ev['t'])})", np.clip(img, -lim, lim), "bwr"))
            labels = np.bincount(ev["label"], minlength=4)
            print("event labels (signal, shot, leak, hot):", labels.tolist())

    fig, axes = plt.subplots(1, len(panels), figsize=(3.2 * len(panels), 3.0))
    for ax, (title, img, cmap) in zip(np.atleast_1d(axes), panels):
        ax.imshow(img, cmap=cmap)
        ax.set_title(title, fontsize=8)
        ax.axis("off")
    fig.suptitle(f"{rec.sequence} at {rec.lux:g} lx, t = {t * 1e3:.1f} ms", fontsize=10)
    fig.tight_layout()
    fig.savefig(args.out, dpi=120)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    try:
        main()
    except SimSpadError as exc:  # a missing or invalid recording: one line, as the simspad command prints it
        print(f"{Path(__file__).name}: error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
