"""``--help`` of evaluate, leaderboard and score lists the method names and says where results go."""

from click.testing import CliRunner

from simspad.cli.app import METHOD_NAMES_HELP, cli
from simspad.methods.registry import BUILTIN_METHODS


def _help(command: str) -> str:
    res = CliRunner().invoke(cli, [command, "--help"], terminal_width=200)
    assert res.exit_code == 0, res.output
    return " ".join(res.output.split())


def test_help_lists_every_builtin_method_and_the_output_defaults():
    assert METHOD_NAMES_HELP.split(", ") == [m.name for m in BUILTIN_METHODS]
    ev = _help("evaluate")
    assert all(m.name in ev for m in BUILTIN_METHODS) and "required; no default" in ev
    assert "default: the first RESULTS_DIR" in _help("leaderboard")
    assert "_results beside the submission" in _help("score")
