"""The leaderboard's model: the merged results of one or more results directories (:class:`Board`).

When two directories score the same method on the same recording, the later one wins. Methods scored on every
recording of the board are ranked by mean PSNR over all recordings (highest first); methods that cover only part
of it (a submission of a few recordings, failed runs) are listed after them, flagged, and never marked best: a
mean over an easier subset is not comparable. Per cell (method, scene, lux) the PSNR is the mean over the
recordings of that scene and light level. Methods scored without absolute scale (after the per-frame log-affine
alignment of :mod:`simspad.evaluate.metrics`) are labelled with a dagger.

Recordings without the speed attributes (datasets made before the speed axis) count as speed factor 1 with an
unknown image speed (NaN).
"""

from __future__ import annotations

import json
import math
import os
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from simspad import defaults
from simspad.errors import SimSpadError
from simspad.io.results_dir import read_csv
from simspad.io.safe_paths import confined_path

DAGGER = "†"


@dataclass
class Board:
    """The merged results: rows, methods (in ranking order), (scene, lux) columns and per-method info.

    Scene columns carry the speed (:func:`scene_column`): ``fan`` and ``fan ×16`` are two columns."""

    rows: list[dict]
    methods: list[str]
    columns: list[tuple[str, float]]
    info: dict[str, dict]
    psnr: dict[tuple[str, str, float], float]
    sources: dict[tuple[str, str], Path]
    mtf50: dict[tuple[str, str, float], float]
    recordings: list[str] = field(default_factory=list)
    """Every recording any method was scored on, or that a scored submission left out."""
    star: dict[tuple[str, str, float], dict[str, float]] = field(default_factory=dict)
    """Siemens-star figures (``mtf*_cyc_px`` columns of results.csv) per (method, scene column, lux)."""
    about: list[dict] = field(default_factory=list)
    """Per results directory, what its ``results.json`` says it is (:func:`results_about`), in input order."""
    recording_info: dict[str, dict] = field(default_factory=dict)
    """Per recording, what a ``results.json`` says of it (resolution, duration, seed, render settings)."""

    def coverage(self, method: str) -> int:
        """How many recordings of the board ``method`` was scored on (failed runs not counted)."""
        return len(self.info[method]["recordings"])

    def is_partial(self, method: str) -> bool:
        """Whether ``method`` covers only part of the board's recordings."""
        return self.coverage(method) < len(self.recordings)

    def ranked(self) -> list[str]:
        """The methods that cover every recording (the ones ranked and eligible for "best")."""
        return [m for m in self.methods if not self.is_partial(m)]


def load_results(results_dirs) -> list[tuple[dict, Path]]:
    """Rows of every ``results.csv`` with the directory they came from; later directories override."""
    merged: dict[tuple[str, str], tuple[dict, Path]] = {}
    for d in results_dirs:
        d = Path(d)
        csv_path = d / "results.csv"
        if not csv_path.is_file():
            raise SimSpadError("not a results directory (results.csv missing)", path=d)
        confined_path(d, "results.csv", source=d, field="results.csv")  # a link out of d is not read
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


def _float(v, default: float) -> float:
    return float(v) if isinstance(v, (int, float)) and math.isfinite(v) else default


def normalise_speed(row: dict) -> dict:
    """Fill ``speed_factor`` (1 when absent) and ``image_speed_px_s`` (NaN when absent) of a results row."""
    row["speed_factor"] = _float(row.get("speed_factor"), 1.0)
    row["image_speed_px_s"] = _float(row.get("image_speed_px_s"), float("nan"))
    return row


def scene_column(row: dict) -> str:
    """The scene's column label: its name, with ``×k`` for a speed factor k other than 1 (each speed is a column,
    so a table never averages a scene's slow and fast recordings together)."""
    return row["scene"] if row["speed_factor"] == 1.0 else f"{row['scene']} ×{row['speed_factor']:g}"


def missing_recordings(results_dirs) -> set[str]:
    """Recordings a scored submission left out (``missing_recordings`` of its ``results.json``)."""
    out: set[str] = set()
    for d in results_dirs:
        if (Path(d) / "results.json").exists():
            confined_path(d, "results.json", source=d, field="results.json")
        try:
            meta = json.loads((Path(d) / "results.json").read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue
        miss = meta.get("missing_recordings") if isinstance(meta, dict) else None
        if isinstance(miss, list):
            out.update(str(m) for m in miss)
    return out


def _results_json(d) -> dict:
    try:
        meta = json.loads((Path(d) / "results.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return meta if isinstance(meta, dict) else {}


def results_about(results_dirs) -> tuple[list[dict], dict[str, dict]]:
    """What each results directory's ``results.json`` says it is — kind (evaluate or score), dataset name, spec
    hash, seed, SimSPAD version, creation time, evaluation rate, methods — and what it says of each recording
    (the later directory wins). Missing or unreadable metadata gives empty values, never an error: the board
    still shows the scores, and says what it does not know."""
    about, recordings = [], {}
    for d in results_dirs:
        meta = _results_json(d)
        ds = meta.get("dataset") if isinstance(meta.get("dataset"), dict) else {}
        about.append({"directory": Path(d).name, "kind": meta.get("kind"), "dataset": ds.get("name"),
                      "spec_hash": ds.get("spec_hash"), "seed": ds.get("seed"),
                      "simspad_version": meta.get("simspad_version"), "created_utc": meta.get("created_utc"),
                      "rate_hz": meta.get("rate_hz"),
                      "methods": [str(m) for m in meta.get("methods", []) if isinstance(m, str)]})
        for r in meta.get("recordings", []) if isinstance(meta.get("recordings"), list) else []:
            if isinstance(r, dict) and isinstance(r.get("recording"), str):
                recordings[r["recording"]] = r
    return about, recordings


def mean_finite(values) -> float:
    v = [x for x in values if isinstance(x, float) and math.isfinite(x)]
    return float(np.mean(v)) if v else float("nan")


def _check_size(rows: list[dict], results_dirs) -> None:
    """Refuse, before any plot, a leaderboard whose plots and tables would take minutes: more methods, table
    columns or regime cells than :mod:`simspad.defaults` allows (``SIMSPAD_IGNORE_LIMITS=1`` lifts them)."""
    if os.environ.get("SIMSPAD_IGNORE_LIMITS", "") == "1":
        return
    luxes = {r["lux"] for r in rows}
    speeds = {r["speed_factor"] for r in rows}
    counts = (("methods", len({r["method"] for r in rows}), defaults.MAX_LEADERBOARD_METHODS, "method",
               "each is a line of every plot and a heatmap panel"),
              (f"light-level × speed cells ({len(luxes)} × {len(speeds)})", len(luxes) * len(speeds),
               defaults.MAX_LEADERBOARD_REGIME_CELLS, "lux", "each is a cell of every method's heatmap"),
              ("scene × speed × lux columns", len({(r["scene"], r["speed_factor"], r["lux"]) for r in rows}),
               defaults.MAX_LEADERBOARD_COLUMNS, "scene", "each is a column of every table"))
    for what, n, limit, field_name, why in counts:
        if n > limit:
            raise SimSpadError(f"{n} {what}, above the {limit} one leaderboard shows ({why}); pass fewer results "
                               "directories or set SIMSPAD_IGNORE_LIMITS=1 to try anyway",
                               path=Path(results_dirs[0]) / "results.csv", field=field_name)


def build_board(results_dirs) -> Board:
    """Merge the ``results.csv`` of ``results_dirs`` (later ones override) into a :class:`Board`."""
    loaded = load_results(results_dirs)
    rows = [normalise_speed(r) for r, _ in loaded]
    _check_size(rows, results_dirs)
    sources = {(r["method"], r["recording"]): d for r, d in loaded}
    info: dict[str, dict] = {}
    per_cell: dict[tuple[str, str, float], list[float]] = defaultdict(list)
    for r in rows:
        m = info.setdefault(r["method"], {"label": r.get("label") or r["method"], "sensors": r.get("sensors", ""),
                                          "absolute_scale": r.get("absolute_scale", True), "bw_khz": [],
                                          "bw_bits": [], "psnr": [], "ssim": [], "errors": [],
                                          "bw_khz_by_lux": defaultdict(list), "bw_bits_by_lux": defaultdict(list),
                                          "recordings": set()})
        if r.get("error"):
            m["errors"].append(r["error"])
            continue
        m["recordings"].add(r["recording"])
        per_cell[(r["method"], scene_column(r), float(r["lux"]))].append(r["psnr_db"])
        m["bw_khz"].append(r.get("bandwidth_khz_per_pixel", float("nan")))
        m["bw_bits"].append(r.get("bandwidth_bits_per_pixel_s", float("nan")))
        m["bw_khz_by_lux"][float(r["lux"])].append(r.get("bandwidth_khz_per_pixel", float("nan")))
        m["bw_bits_by_lux"][float(r["lux"])].append(r.get("bandwidth_bits_per_pixel_s", float("nan")))
        m["psnr"].append(r["psnr_db"])
        m["ssim"].append(r.get("ssim", float("nan")))
    psnr = {k: mean_finite(v) for k, v in per_cell.items()}
    mtf = {(r["method"], scene_column(r), float(r["lux"])): r.get("mtf50_cyc_px", float("nan")) for r in rows
           if not r.get("error") and math.isfinite(r.get("mtf50_cyc_px", float("nan")))}
    star = {}
    for r in rows:
        figures = {k: v for k, v in r.items() if k.startswith("mtf") and k.endswith("_cyc_px")
                   and isinstance(v, float) and math.isfinite(v)}
        if figures and not r.get("error"):
            star[(r["method"], scene_column(r), float(r["lux"]))] = figures
    columns = sorted({(scene_column(r), float(r["lux"])) for r in rows})
    for m in info.values():
        m["bw_khz_mean"] = mean_finite(m["bw_khz"])
        m["bw_bits_mean"] = mean_finite(m["bw_bits"])
        m["psnr_mean"] = mean_finite(m["psnr"])
        m["ssim_mean"] = mean_finite(m["ssim"])
    recordings = sorted({r["recording"] for r in rows} | missing_recordings(results_dirs))
    methods = sorted(info, key=lambda k: (len(info[k]["recordings"]) < len(recordings),
                                          -(info[k]["psnr_mean"]) if math.isfinite(info[k]["psnr_mean"])
                                          else math.inf, k))
    about, recording_info = results_about(results_dirs)
    return Board(rows, methods, columns, info, psnr, sources, mtf, recordings, star, about, recording_info)


def best_of(values: dict[str, float], higher: bool = True) -> set[str]:
    finite = {k: v for k, v in values.items() if math.isfinite(v)}
    if not finite:
        return set()
    target = max(finite.values()) if higher else min(finite.values())
    return {k for k, v in finite.items() if v == target}


def method_label(board: Board, method: str) -> str:
    """The display label: dagger for methods without absolute scale, ``(partial: k/N)`` for partial coverage."""
    i = board.info[method]
    text = f"{i['label']}{'' if i['absolute_scale'] else ' ' + DAGGER}"
    if board.is_partial(method):
        text += f" (partial: {board.coverage(method)}/{len(board.recordings)})"
    return text


def best_ranked(board: Board, values: dict[str, float], higher: bool = True) -> set[str]:
    """:func:`best_of` among the methods that cover every recording of the board (none when no method does).

    Every method that covers the board was scored on the same recordings, so any column, cell or mean compares
    like with like among them; a partial method is never eligible, even in a column it happens to cover (its
    presence there says nothing about the rest of the board, and a 1-recording submission bolded beside complete
    methods reads as a claim it cannot back).
    """
    ranked = set(board.ranked())
    return best_of({k: v for k, v in values.items() if k in ranked}, higher)


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
