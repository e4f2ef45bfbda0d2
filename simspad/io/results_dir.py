"""The results directory shared by ``simspad evaluate``, ``simspad score`` and ``simspad leaderboard``.

Layout (one directory per run; each file written whole under a temporary name, then moved in; files that
another command or the user put there are kept: :mod:`simspad.io.output_dirs`)::

    results.csv        one row per method × recording (columns RESULT_COLUMNS: the fields of ResultRow)
    frames.csv         per-frame detail (FRAME_COLUMNS)
    mtf.csv            MTF curves of Siemens-star recordings (MTF_COLUMNS), when any
    results.json       metadata: version, time, target, evaluation rate, protocol constants, rows
    images/<rec>/gt.png, images/<rec>/<method>.png, images/<rec>/<method>_vs_gt.png
                       display-mapped crops of the chosen instant (ground truth beside the method)
    reconstructions/<rec>/<method>.h5
                       the reconstructions as scored (/t [N] float64 s, /flux [N,H,W] float32 ph s⁻¹ m⁻²;
                       written by :class:`simspad.io.reconstructions.ReconstructionSink`)
    .simspad-evaluate or .simspad-score
                       the marker: which command wrote the folder and the files it wrote
    .simspad.lock      held by the one command writing the folder
"""

from __future__ import annotations

import csv
import hashlib
import json
import math
import os
import re
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
from PIL import Image

from simspad import __version__, defaults
from simspad.errors import InputError
from simspad.io.csv_cells import csv_safe, csv_unescape
from simspad.io.output_dirs import claim_output_dir
from simspad.io.provenance import created_datetime
from simspad.io.safe_paths import confined_path

_NAN = float("nan")


@dataclass
class ResultRow:
    """One row of ``results.csv``: one method scored on one recording (docs/format.md, results section).

    The fields are the columns, in their order (:data:`RESULT_COLUMNS`). ``simspad evaluate`` and ``simspad score``
    start a row with :meth:`for_recording` and fill in what the run measured (:meth:`update`); a metric the run
    did not measure stays NaN.

    Attributes
    ----------
    method, label, sensors : str
        Method id, display name, sensor letters (``S+E``...).
    scene, sequence, recording : str
        What was scored (``recording`` relative to the dataset).
    lux : float
        The recording's illuminance, lx.
    speed_factor, image_speed_px_s : float
        The recording's retiming factor and median image speed, px s⁻¹.
    psnr_db, ssim : float
        Means over the evaluated instants.
    mtf_at_0p25_cyc_px, mtf_at_0p40_cyc_px, mtf50_cyc_px : float
        Siemens-star figures (cycles per pixel for MTF50).
    bandwidth_khz_per_pixel, bandwidth_bits_per_pixel_s : float
        The method's readouts per pixel per second / 1000, bits per pixel per second.
    absolute_scale : bool
        Scored as is (True) or after a per-frame affine fit in log space.
    n_frames : int
        Instants scored.
    runtime_s : float
        Wall time of the method, s.
    white_point_ph_s_m2 : float
        The sequence's white point, ph s⁻¹ m⁻².
    image, error : str
        Comparison image (relative path), error message of a failed run.
    params : str or None
        The method's parameters as compact JSON ("" for the defaults); None where the run has none to state (a
        submission): the CSV cell is empty either way, ``results.json`` holds null.
    """

    method: str
    label: str
    sensors: str
    scene: str
    sequence: str
    lux: float
    recording: str
    speed_factor: float
    image_speed_px_s: float
    psnr_db: float = _NAN
    ssim: float = _NAN
    mtf_at_0p25_cyc_px: float = _NAN
    mtf_at_0p40_cyc_px: float = _NAN
    mtf50_cyc_px: float = _NAN
    bandwidth_khz_per_pixel: float = _NAN
    bandwidth_bits_per_pixel_s: float = _NAN
    absolute_scale: bool = True
    n_frames: int = 0
    runtime_s: float = _NAN
    white_point_ph_s_m2: float = _NAN
    image: str = ""
    error: str = ""
    params: str | None = None

    @classmethod
    def for_recording(cls, method: str, entry, **columns) -> "ResultRow":
        """A row of ``method`` on the recording ``entry`` (a :class:`simspad.evaluate.recordings.RecordingEntry`:
        its ``scene``, ``sequence``, ``lux``, ``rel``, ``speed_factor`` and ``image_speed_px_s``); the label is
        the method id until ``columns`` (any other column) say otherwise."""
        return cls(method=method, label=columns.pop("label", method), sensors=columns.pop("sensors", ""),
                   scene=entry.scene, sequence=entry.sequence, lux=entry.lux, recording=entry.rel,
                   speed_factor=entry.speed_factor, image_speed_px_s=entry.image_speed_px_s, **columns)

    def update(self, **columns) -> None:
        """Set columns by name (TypeError for a name that is not a column)."""
        for name, value in columns.items():
            if name not in _COLUMN_SET:
                raise TypeError(f"results.csv has no column {name!r}")
            setattr(self, name, value)

    def to_dict(self) -> dict:
        """The row as ``{column: value}``, in column order."""
        return {c: getattr(self, c) for c in RESULT_COLUMNS}


#: The columns of ``results.csv``, in order: the fields of :class:`ResultRow`.
RESULT_COLUMNS = tuple(f.name for f in fields(ResultRow))
_COLUMN_SET = frozenset(RESULT_COLUMNS)
FRAME_COLUMNS = ("method", "recording", "frame", "t_s", "psnr_db", "ssim", "fit_a", "fit_b")
MTF_COLUMNS = ("method", "recording", "freq_cyc_px", "mtf")
CROP_PX = 256


def slug(text: str) -> str:
    """A filesystem-safe name for ``text`` (a short hash is appended when characters had to be replaced)."""
    s = re.sub(r"[^A-Za-z0-9_.-]", "_", str(text)).strip(".") or "_"
    if s != text:
        s = f"{s[:60]}-{hashlib.sha1(str(text).encode()).hexdigest()[:8]}"
    return s


def _fmt(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "nan" if math.isnan(v) else repr(v)
    return "" if v is None else str(v)


def write_csv(path: Path, columns, rows) -> None:
    """``columns`` then one line per row; text a spreadsheet would run as a formula is escaped
    (:func:`simspad.io.csv_cells.csv_safe`; :func:`read_csv` undoes it)."""
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(columns)
        for r in rows:
            w.writerow([_fmt(csv_safe(r.get(c))) for c in columns])


def _parse(col: str, v: str):
    if col in ("method", "label", "sensors", "scene", "sequence", "recording", "image", "error", "params"):
        return v
    if col == "absolute_scale":
        return v.strip().lower() in ("true", "1", "yes")
    if col in ("n_frames", "frame"):
        return int(v) if v not in ("", "nan") else 0
    try:
        return float(v)
    except ValueError:
        return float("nan")


def read_csv(path: Path) -> list[dict]:
    """Rows of a results CSV with numbers parsed (unknown columns kept as text); an ``image`` must name a file
    inside the results directory (InputError otherwise, as for malformed CSV). More than
    :data:`~simspad.defaults.MAX_RESULTS_ROWS` rows are refused while reading (``SIMSPAD_IGNORE_LIMITS=1``
    lifts it)."""
    path = Path(path)
    limit = math.inf if os.environ.get("SIMSPAD_IGNORE_LIMITS", "") == "1" else defaults.MAX_RESULTS_ROWS
    rows = []
    try:
        with open(path, newline="", encoding="utf-8") as f:
            for row in csv.DictReader(f):
                if len(rows) >= limit:
                    raise InputError(f"more than {defaults.MAX_RESULTS_ROWS} rows, the limit of one results "
                                     "table (set SIMSPAD_IGNORE_LIMITS=1 to try anyway)", path=path)
                rows.append({k: _parse(k, csv_unescape(v)) for k, v in row.items()})
    except (csv.Error, UnicodeDecodeError) as exc:
        raise InputError(f"not a readable results CSV ({str(exc)[:120]})", path=path) from None
    checked = set()
    for i, row in enumerate(rows):
        if row.get("image") and row["image"] not in checked:
            confined_path(path.parent, row["image"], source=path, field=f"row {i + 2}: image")
            checked.add(row["image"])
    return rows


def save_png(path: Path, img01: np.ndarray) -> None:
    """Write a [H,W] image in [0, 1] as an 8-bit greyscale PNG."""
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.round(np.clip(img01, 0, 1) * 255).astype(np.uint8), mode="L").save(path)


def crop(img: np.ndarray, size: int = CROP_PX) -> np.ndarray:
    """The central ``size``×``size`` crop (the whole image when smaller)."""
    h, w = img.shape[:2]
    y0, x0 = max(0, (h - size) // 2), max(0, (w - size) // 2)
    return img[y0:y0 + size, x0:x0 + size]


def write_images(work_dir: Path, key: str, method: str, images) -> str:
    """Save the GT crop, the method's crop and the pair side by side; return the pair's relative path.

    ``images`` is (method crop, ground-truth crop), both display-mapped to [0, 1]; they go to
    ``images/<key>/gt.png``, ``<method>.png`` and ``<method>_vs_gt.png`` (a 4-pixel white gap between them).
    """
    rec_img, gt_img = images
    d = work_dir / "images" / slug(key)
    save_png(d / "gt.png", gt_img)
    name = slug(method)
    save_png(d / f"{name}.png", rec_img)
    gap = np.ones((gt_img.shape[0], 4), np.float32)
    save_png(d / f"{name}_vs_gt.png", np.hstack([rec_img, gap, gt_img]))
    return (d / f"{name}_vs_gt.png").relative_to(work_dir).as_posix()


def write_results_dir(tmp: Path, kind: str, rows: list[ResultRow], frame_rows: list[dict], mtf_rows: list[dict],
                      meta: dict) -> None:
    """Write the tables and ``results.json`` of a results directory into ``tmp`` (images are written by callers).

    ``results.json`` is built here alone: the header every results folder shares (``format``, ``format_version``,
    ``simspad_version``, ``created_utc`` taken once, here (``$SOURCE_DATE_EPOCH`` when set, as for recordings), and ``kind``: ``"evaluate"`` or ``"score"``), then the
    command's own ``meta``, then ``results``, the rows (NaN as null).
    """
    tmp.mkdir(parents=True, exist_ok=True)
    dicts = [r.to_dict() for r in rows]
    write_csv(tmp / "results.csv", RESULT_COLUMNS, dicts)
    write_csv(tmp / "frames.csv", FRAME_COLUMNS, frame_rows)
    if mtf_rows:
        write_csv(tmp / "mtf.csv", MTF_COLUMNS, mtf_rows)
    doc = {"format": "simspad-results", "format_version": 1, "simspad_version": __version__,
           "created_utc": created_datetime().isoformat(timespec="seconds"), "kind": kind, **meta}
    doc["results"] = [{c: (None if isinstance(v, float) and math.isnan(v) else v) for c, v in r.items()}
                      for r in dicts]
    (tmp / "results.json").write_text(json.dumps(doc, indent=2, sort_keys=True, default=str) + "\n",
                                      encoding="utf-8")


#: The files of a results folder, as written before folders carried a marker (:func:`legacy_results`).
_LEGACY_RESULT_FILES = re.compile(r"(results\.csv|frames\.csv|mtf\.csv|results\.json|images/[^/]+/[^/]+\.png"
                                  r"|reconstructions/[^/]+/[^/]+\.h5)")


def legacy_results(command: str):
    """Recognise a results folder that ``simspad <command>`` wrote before markers: its ``results.json`` says
    ``format`` ``simspad-results`` and ``kind`` ``command``; its own files are those of the layout above."""

    def recognise(path: Path) -> set[str] | None:
        try:
            meta = json.loads((path / "results.json").read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None
        if not isinstance(meta, dict) or meta.get("format") != "simspad-results" or meta.get("kind") != command:
            return None
        return {rel for p in path.rglob("*") if p.is_file() and not p.is_symlink()
                and _LEGACY_RESULT_FILES.fullmatch(rel := p.relative_to(path).as_posix())}

    return recognise


def check_output_dir(out_dir: Path, command: str) -> None:
    """Refuse ``out_dir`` unless it is new, empty or a results folder ``simspad <command>`` wrote (its marker
    ``.simspad-<command>``, or an older one's ``results.json``); a link or special file is refused too."""
    claim_output_dir(out_dir, command, legacy=legacy_results(command))
