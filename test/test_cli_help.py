"""`pearl --help` and every subcommand's --help render (argparse formats help texts)."""
import pytest

from pearl_pomdp.cli import _command_modules, main

COMMANDS = sorted(m.COMMAND for m in _command_modules())


def test_top_level_help_lists_every_command(capsys):
    with pytest.raises(SystemExit) as info:
        main(["--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    for name in COMMANDS:
        assert name in out
    assert {"solve", "simulate", "plan", "demo", "experiment", "replay", "record", "bag-info", "launch", "run"} <= set(COMMANDS)


@pytest.mark.parametrize("command", COMMANDS)
def test_each_command_help(command, capsys):
    with pytest.raises(SystemExit) as info:
        main([command, "--help"])
    assert info.value.code == 0
    assert f"pearl {command}" in capsys.readouterr().out
