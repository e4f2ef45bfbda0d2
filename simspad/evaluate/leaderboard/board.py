"""The leaderboard's model: the merged results of one or more results directories (:class:`Board`).

When two directories score the same method on the same recording, the later one wins. Methods are ranked by
mean PSNR over all recordings (highest first); per cell (method, scene, lux) the PSNR is the mean over the
recordings of that scene and light level. Methods scored without absolute scale (after the log-affine alignment
of DESIGN §8) are labelled with a dagger.
"""

from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from simspad.errors import SimSpadError
from simspad.io.results_dir import read_csv

DAGGER = "†"


@dataclass


class Board:
    """The merged results: rows, methods (in ranking order), (scene, lux) columns and per-method info."""

    rows: list[dict]
    methods: list[str]
    columns: list[tuple[str, float]]
    info: dict[str, dict]
    psnr: dict[tuple[str, str, float], float]
    sources: dict[tuple[str, str], Path]
    mtf50: dict[tuple[str, str, float], float]


def load_results(results_dirs) -> list[tuple[dict, Path]]:
    """Rows of every ``results.csv`` with the directory they came from; later directories override."""
    merged: dict[tuple[str, str], tuple[dict, Path]] = {}
    for d in results_dirs:
        d = Path(d)
        csv_path = d / "results.csv"
        if not csv_path.is_file():
            raise SimSpadError("not a results directory (results.csv missing)", path=d)
        try:
            rows = read_csv(csv_path)
        except (OSError, UnicodeDecodeError, ValueError) as exc:
            raise SimSpadError(f"unreadable ({exc})", path=csv_path) from None
        for i, r in enumerate(rows):
            for col in ("method", "scene", "lux", "psnr_db", "recording"):
                if col not in r:
                    raise SimSpadError("column missing", path=csv_path, field=col)
            merged[(r["method"], r["recording"])] = (r, d)
    if not merged:
        raise SimSpadError("no results rows", path=Path(results_dirs[0]))
    return list(merged.values())


def mean_finite(values) -> float:
    v = [x for x in values if isinstance(x, float) and math.isfinite(x)]
    return float(np.mean(v)) if v else float("nan")


def build_board(results_dirs) -> Board:
    """Merge the ``results.csv`` of ``results_dirs`` (later ones override) into a :class:`Board`."""
    loaded = load_results(results_dirs)
    rows = [r for r, _ in loaded]
    sources = {(r["method"], r["recording"]): d for r, d in loaded}
    info: dict[str, dict] = {}
    per_cell: dict[tuple[str, str, float], list[float]] = defaultdict(list)
    for r in rows:
        m = info.setdefault(r["method"], {"label": r.get("label") or r["method"], "sensors": r.get("sensors", ""),
                                          "absolute_scale": r.get("absolute_scale", True), "bw_khz": [],
                                          "bw_bits": [], "psnr": [], "ssim": [], "errors": [],
                                          "bw_khz_by_lux": defaultdict(list), "bw_bits_by_lux": defaultdict(list)})
        if r.get("error"):
            m["errors"].append(r["error"])
            continue
        per_cell[(r["method"], r["scene"], float(r["lux"]))].append(r["psnr_db"])
        m["bw_khz"].append(r.get("bandwidth_khz_per_pixel", float("nan")))
        m["bw_bits"].append(r.get("bandwidth_bits_per_pixel_s", float("nan")))
        m["bw_khz_by_lux"][float(r["lux"])].append(r.get("bandwidth_khz_per_pixel", float("nan")))
        m["bw_bits_by_lux"][float(r["lux"])].append(r.get("bandwidth_bits_per_pixel_s", float("nan")))
        m["psnr"].append(r["psnr_db"])
        m["ssim"].append(r.get("ssim", float("nan")))
    psnr = {k: mean_finite(v) for k, v in per_cell.items()}
    mtf = {(r["method"], r["scene"], float(r["lux"])): r.get("mtf50_cyc_px", float("nan")) for r in rows
           if not r.get("error") and math.isfinite(r.get("mtf50_cyc_px", float("nan")))}
    columns = sorted({(r["scene"], float(r["lux"])) for r in rows})
    for m in info.values():
        m["bw_khz_mean"] = mean_finite(m["bw_khz"])
        m["bw_bits_mean"] = mean_finite(m["bw_bits"])
        m["psnr_mean"] = mean_finite(m["psnr"])
        m["ssim_mean"] = mean_finite(m["ssim"])
    methods = sorted(info, key=lambda k: (-(info[k]["psnr_mean"]) if math.isfinite(info[k]["psnr_mean"])
                                          else math.inf, k))
    return Board(rows, methods, columns, info, psnr, sources, mtf)


def best_of(values: dict[str, float], higher: bool = True) -> set[str]:
    finite = {k: v for k, v in values.items() if math.isfinite(v)}
    if not finite:
        return set()
    target = max(finite.values()) if higher else min(finite.values())
    return {k for k, v in finite.items() if v == target}


def method_label(board: Board, method: str) -> str:
    i = board.info[method]
    return f"{i['label']}{'' if i['absolute_scale'] else ' ' + DAGGER}"


def fmt_number(v: float, digits: int = 2) -> str:
    return f"{v:.{digits}f}" if isinstance(v, float) and math.isfinite(v) else "–"


def fmt_bandwidth(v: float) -> str:
    if not (isinstance(v, float) and math.isfinite(v)):
        return "–"
    return f"{v:.3g}" if v < 1000 else f"{v:.0f}"


def lux_levels(board: Board) -> list[float]:
    return sorted({lux for _, lux in board.columns})


def lux_means(board: Board) -> dict[str, dict[float, float]]:
    out: dict[str, dict[float, float]] = {}
    for m in board.methods:
        out[m] = {lux: mean_finite([board.psnr.get((m, s, l), float("nan")) for s, l in board.columns if l == lux])
                  for lux in lux_levels(board)}
    return out


def failed_runs(board: Board) -> list[tuple[str, str]]:
    return [(board.info[m]["label"], e) for m in board.methods for e in board.info[m]["errors"]]
