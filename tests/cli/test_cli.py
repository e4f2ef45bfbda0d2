"""The CLI frame: help lists the subcommands; bad input gives one line and exit 2; --debug shows tracebacks."""

from __future__ import annotations

from simspad.cli import main

SUBCOMMANDS = ("render", "simulate", "generate", "evaluate", "leaderboard", "score", "snr", "info", "scenes")


def test_help_lists_subcommands(simspad_cli):
    proc = simspad_cli.run("--help")
    assert proc.returncode == 0
    commands = proc.stdout.split("Commands:")[1]
    for name in SUBCOMMANDS:
        assert f"\n  {name} " in commands, name


def test_version(capsys):
    from simspad import __version__

    assert main(["--version"]) == 0
    assert __version__ in capsys.readouterr().out


def test_info_on_missing_path_is_one_line(tmp_path, capsys):
    assert main(["info", str(tmp_path / "nothing.h5")]) == 2
    captured = capsys.readouterr()
    assert captured.err == f"simspad: error: {tmp_path / 'nothing.h5'}: no such file or directory\n"


def test_info_on_unknown_kind_of_file(tmp_path, capsys):
    p = tmp_path / "notes.pdf"
    p.write_bytes(b"%PDF")
    assert main(["info", str(p)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unknown kind of file '.pdf'" in err
    d = tmp_path / "folder"
    d.mkdir()
    assert main(["info", str(d)]) == 2
    assert "no manifest.json" in capsys.readouterr().err


def test_bad_input_has_no_traceback_unless_debug(tmp_path, simspad_cli):
    bad = tmp_path / "t.csv"
    bad.write_text("t,tx,ty,tz,qx,qy,qz,qw\n1,0,0,0,0,0,0,1\n0,0,0,0,0,0,0,1\n")
    plain = simspad_cli.run("info", bad)
    assert plain.returncode == 2
    assert plain.stderr.count("\n") == 1 and "Traceback" not in plain.stderr
    assert f"{bad}: line 3: " in plain.stderr
    debug = simspad_cli.run("--debug", "info", bad)
    assert debug.returncode != 0 and "Traceback" in debug.stderr and "InputError" in debug.stderr


def test_usage_error_exits_nonzero(capsys):
    assert main(["info"]) == 2
    assert "Missing argument" in capsys.readouterr().err


def test_help_names_the_real_choices_and_output_defaults(capsys):
    """The help texts list the bundled specs, scenes and presets that exist, and where outputs go by default."""
    from simspad.bundled import builtin_spec_names
    from simspad.scenes.library import builtin_scene_names
    from simspad.sensors.presets import PRESETS

    def help_of(command):
        assert main([command, "--help"]) == 0
        return " ".join(capsys.readouterr().out.split())  # click wraps lines

    generate = help_of("generate")
    assert all(name in generate for name in builtin_spec_names()) and "output/mini" in generate
    render = help_of("render")
    assert all(name in render for name in builtin_scene_names())
    simulate = help_of("simulate")
    assert all(preset in simulate for presets in PRESETS.values() for preset in presets)
    assert f"sensor kinds, of: {', '.join(PRESETS)}." in simulate  # the sensor table's kinds
    assert "output/snr.png" in help_of("snr")


def test_info_and_generate_accept_a_bundled_spec_name(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # not the checkout: the name resolves through the package data
    assert main(["info", "mini"]) == 0
    assert "mini" in capsys.readouterr().out
    assert main(["info", "no-such-spec"]) == 2
    assert "no-such-spec: no such file or directory" in capsys.readouterr().err
