"""Mutation check (issue 36, goal 6): each formula flip that once survived the suite must now fail the test named
for it.

Each case copies the package and the tests into a temporary directory, applies one flip to the copy (the original
text must occur exactly once, so a refactor that moves it makes this test say so instead of passing vacuously),
and runs only the targeted test there in a child process, whose ``simspad`` is the copy. The flip must make that
test fail (pytest exit status 1: a failed assertion, not an import or collection error).

| flip | file | caught by |
|---|---|---|
| photoreceptor term τ/(τ+Δt) → Δt/(τ+Δt) | methods/akf.py | test_akf: every term on, eight neighbours |
| isolation neighbourhood rows range(-1, 2) → range(-1, 1) | methods/akf.py | the same |
| isolation neighbourhood columns range(-1, 2) → range(-1, 1) | methods/akf.py | the same |
| ADC rounding rint → floor | sensors/frames/model.py | test_frames: exact quantisation |
| ground-truth log floor from the frame's max, not its p99 | evaluate/metrics.py | ground truth scores the cap |
| a partial method eligible for a column's best mark | evaluate/leaderboard/tables.py | test_fair_ranks |
"""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

AKF_HAND = "tests/methods/test_akf.py::test_event_noise_with_every_term_on_and_all_eight_neighbours_firing"
AKF_REF = "tests/methods/test_akf.py::test_event_kernel_matches_the_independent_vectorised_reference"

#: (id, file, original text, flipped text, the test that must fail)
MUTATIONS = [
    ("akf_bandwidth_term", "simspad/methods/akf.py", "frac = tau_pr[i] / (tau_pr[i] + dtp)",
     "frac = dtp / (tau_pr[i] + dtp)", AKF_HAND),
    ("akf_bandwidth_term_vs_reference", "simspad/methods/akf.py", "frac = tau_pr[i] / (tau_pr[i] + dtp)",
     "frac = dtp / (tau_pr[i] + dtp)", AKF_REF),
    ("akf_neighbour_rows", "simspad/methods/akf.py", "for dy in range(-1, 2):", "for dy in range(-1, 1):",
     AKF_HAND),
    ("akf_neighbour_columns", "simspad/methods/akf.py", "for dx in range(-1, 2):", "for dx in range(-1, 1):",
     AKF_REF),
    ("frames_rint_to_floor", "simspad/sensors/frames/model.py", "dn = np.rint(", "dn = np.floor(",
     "tests/sensors/test_frames.py::test_quantisation_rounds_to_the_nearest_dn_and_clips_exactly"),
    ("score_gt_floor", "simspad/evaluate/metrics.py", "y = _log_floored(gt, log_floor(gt)).ravel()",
     "y = _log_floored(gt, LOG_FLOOR_REL * float(np.max(gt))).ravel()",
     "tests/evaluate/test_score_closed_forms.py::test_the_ground_truth_scores_the_cap_and_ssim_one_both_ways"),
    ("leaderboard_partial_best", "simspad/evaluate/leaderboard/tables.py",
     "best_cols = [best_ranked(board, {m: board.psnr.get((m, s, l), float(\"nan\")) for m in board.methods})",
     "best_cols = [best_of({m: board.psnr.get((m, s, l), float(\"nan\")) for m in board.methods})",
     "tests/evaluate/test_fair_ranks.py::test_a_one_of_n_submission_is_never_bolded_ranked_or_on_a_front"),
]


@pytest.fixture(scope="module")
def pristine_copy(tmp_path_factory):
    """The package, the tests and pyproject.toml copied once (without caches); each case copies this again."""
    root = tmp_path_factory.mktemp("mutants") / "pristine"
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "*.nbi", "*.nbc")
    for name in ("simspad", "tests"):
        shutil.copytree(REPO / name, root / name, ignore=ignore)
    shutil.copy2(REPO / "pyproject.toml", root / "pyproject.toml")
    return root


@pytest.mark.slow
@pytest.mark.parametrize("case", MUTATIONS, ids=[m[0] for m in MUTATIONS])
def test_each_flip_fails_its_targeted_test(case, pristine_copy, tmp_path, child_env):
    _, rel, original, flipped, target = case
    source = (REPO / rel).read_text(encoding="utf-8")
    assert source.count(original) == 1, f"{rel} no longer holds {original!r} exactly once: update MUTATIONS"
    root = tmp_path / "mutant"
    shutil.copytree(pristine_copy, root)
    (root / rel).write_text(source.replace(original, flipped), encoding="utf-8")
    if "best_of(" in flipped:  # the flipped line needs the name the module no longer imports
        text = (root / rel).read_text(encoding="utf-8")
        (root / rel).write_text(text.replace("    best_ranked,\n", "    best_of,\n    best_ranked,\n", 1),
                                encoding="utf-8")
    env = {**child_env, "PYTHONPATH": str(root), "NUMBA_CACHE_DIR": str(tmp_path / "numba_cache")}
    probe = subprocess.run([sys.executable, "-c", "import simspad; print(simspad.__file__)"], cwd=root, env=env,
                           capture_output=True, text=True, timeout=60)
    assert Path(probe.stdout.strip()).is_relative_to(root), probe.stdout + probe.stderr  # the mutant is imported
    res = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-x", target], cwd=root,
                         env=env, capture_output=True, text=True, timeout=600)
    assert res.returncode == 1 and " failed" in res.stdout, (
        f"{rel}: {original!r} -> {flipped!r} was not caught by {target}\n{res.stdout[-3000:]}{res.stderr[-2000:]}")
