"""The CLI with bad files and output folders: one line per problem, exit code 2, no traceback,
and nothing solved before the output folder is known to work."""

import subprocess
import sys
from pathlib import Path

import pytest

import coilrod.scene.runner
from coilrod.scene.cli import main

GOOD = """\
name = "good"
[robot]
length = "40 mm"
diameter = "2 mm"
youngs_modulus = "1 MPa"
magnetization = { preset = "M1" }
[field]
type = "uniform"
B = "5 mT"
[load]
steps = 2
"""

# three mistakes: a boolean in quotes, a sign typo in an axis, a preset with a magnitude
THREE_MISTAKES = """\
[robot]
length = "40 mm"
diameter = "2 mm"
youngs_modulus = "1 MPa"
magnetization = { preset = "M1", magnitude = "64 kA/m" }
[field]
type = "uniform"
B = "5 mT"
direction = "--y"
[output]
figures = "no"
"""


@pytest.fixture
def no_solving(monkeypatch):
    """Any solve fails the test: the command must stop before."""

    def refuse(*args, **kwargs):
        raise AssertionError("a solve started although the command should have stopped")

    monkeypatch.setattr(coilrod.scene.runner, "run_scene", refuse)


def errors(capsys) -> list[str]:
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert all(line.startswith("coilrod: error: ") for line in lines), lines
    return [line.removeprefix("coilrod: error: ") for line in lines]


def write(tmp_path, text, name="scene.toml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


# -- scene files ------------------------------------------------------------------------------
@pytest.mark.parametrize("command", ["check", "run"])
def test_non_utf8_scene(tmp_path, capsys, no_solving, command):
    path = tmp_path / "latin1.toml"
    path.write_bytes(GOOD.replace('"good"', '"caf\xe9"').encode("latin-1"))
    assert main([command, str(path), "--out", str(tmp_path / "out")]) == 2
    lines = errors(capsys)
    assert lines == [f"{path}: not UTF-8 text (byte 0xe9 on line 1); save the scene file as UTF-8"]


def test_utf8_with_bom_is_read(tmp_path, capsys):
    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf" + GOOD.encode("utf-8"))
    assert main(["check", str(path)]) == 0
    assert "valid scene 'good'" in capsys.readouterr().out


def test_directory_as_scene(tmp_path, capsys, no_solving):
    assert main(["run", str(tmp_path), "--out", str(tmp_path / "out")]) == 2
    assert errors(capsys) == [f"{tmp_path}: is a directory, not a scene file (give a .toml file)"]


def test_missing_scene(tmp_path, capsys):
    assert main(["check", str(tmp_path / "nope.toml")]) == 2
    (line,) = errors(capsys)
    assert (
        line == f"{tmp_path / 'nope.toml'}: cannot read the scene file (No such file or directory)"
    )


def test_unreadable_scene(tmp_path, capsys, no_solving, denied):
    path = write(tmp_path, GOOD)
    denied(path, read=True)  # as chmod 0 would, for root too
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 2
    assert errors(capsys) == [f"{path}: cannot read the scene file (Permission denied)"]
    assert not (tmp_path / "out").exists()


def test_every_mistake_on_its_own_line(tmp_path, capsys, no_solving):
    path = write(tmp_path, THREE_MISTAKES)
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 2
    lines = errors(capsys)
    assert [line.split(":")[0] for line in lines[:-1]] == [
        "robot.magnetization.magnitude",
        "field.direction",
        "output.figures",
    ]
    # the file is named on a line of its own (the problems keep their key first); was absent
    assert lines[-1] == f"{path}: the scene file with the 3 problems above"
    assert not (tmp_path / "out").exists()  # an invalid scene creates no output folder


# -- output folders ---------------------------------------------------------------------------
@pytest.mark.parametrize("command", ["run", "check"])
def test_out_is_an_existing_file(tmp_path, capsys, no_solving, command):
    scene = write(tmp_path, GOOD)
    out = write(tmp_path, "results", name="results.txt")
    assert main([command, str(scene), "--out", str(out)]) == 2
    assert errors(capsys) == [
        f"--out: {out} is an existing file, not a folder; give a folder (new or existing) for "
        "the results"
    ]
    assert out.read_text() == "results"


def test_out_below_a_file(tmp_path, capsys, no_solving):
    scene = write(tmp_path, GOOD)
    blocker = write(tmp_path, "x", name="blocker")
    assert main(["run", str(scene), "--out", str(blocker / "sub" / "out")]) == 2
    assert errors(capsys) == [
        f"--out: cannot create the folder {blocker / 'sub' / 'out'}: {blocker} is a file"
    ]


def test_scene_and_out_problems_reported_together(tmp_path, capsys, no_solving):
    scene = write(tmp_path, THREE_MISTAKES)
    out = write(tmp_path, "", name="out")
    assert main(["run", str(scene), "--out", str(out)]) == 2
    lines = errors(capsys)
    assert len(lines) == 5
    assert lines[3] == f"{scene}: the scene file with the 3 problems above"
    assert lines[-1].startswith("--out: ")


def test_unwritable_out(tmp_path, capsys, no_solving, denied):
    scene = write(tmp_path, GOOD)
    locked = tmp_path / "locked"
    locked.mkdir()
    denied(locked)  # as chmod 0o555 would, for root too
    assert main(["run", str(scene), "--out", str(locked)]) == 2
    assert errors(capsys) == [f"--out: cannot write in {locked} (permission denied)"]
    assert main(["run", str(scene), "--out", str(locked / "new")]) == 2
    assert errors(capsys) == [f"--out: cannot create folders in {locked} (permission denied)"]
    assert main(["check", str(scene), "--out", str(locked / "new")]) == 2
    assert errors(capsys) == [f"--out: cannot create folders in {locked} (permission denied)"]
    assert main(["demo", "--out", str(locked / "demo"), "--quiet"]) == 2
    (line,) = errors(capsys)
    assert line.startswith(f"--out: cannot create the folder {locked / 'demo'}")
    assert list(locked.iterdir()) == []


def test_demo_out_is_an_existing_file(tmp_path, capsys, no_solving):
    out = write(tmp_path, "", name="demo")
    assert main(["demo", "--out", str(out), "--quiet"]) == 2
    (line,) = errors(capsys)
    assert line == f"--out: cannot create the folder {out / 'M1'}: {out} is a file"


def test_run_creates_the_out_folder_before_solving(tmp_path, capsys, monkeypatch):
    scene = write(tmp_path, GOOD)
    out = tmp_path / "a" / "b"
    seen = {}

    def stop(scene, **kwargs):
        seen["out exists at the first solve"] = out.is_dir()
        raise KeyboardInterrupt

    monkeypatch.setattr(coilrod.scene.runner, "run_scene", stop)
    assert main(["run", str(scene), "--out", str(out), "--quiet"]) == 130
    assert seen == {"out exists at the first solve": True}
    assert list(out.iterdir()) == []  # the write test left nothing behind
    assert "coilrod: interrupted" in capsys.readouterr().err


def test_check_with_out_creates_nothing(tmp_path, capsys):
    scene = write(tmp_path, GOOD)
    out = tmp_path / "new" / "folder"
    assert main(["check", str(scene), "--out", str(out)]) == 0
    assert f"results can be written to {out}" in capsys.readouterr().out
    assert not (tmp_path / "new").exists()


# -- check stops where run would ----------------------------------------------------------------
UNSOLVABLE = {
    "zero field": GOOD.replace('B = "5 mT"', 'B = "0 mT"'),
    # (the rod's default model takes the spatial rod for it; the planar rod has nothing)
    "field out of plane": GOOD.replace('B = "5 mT"', 'B = "5 mT"\ndirection = "z"')
    + '[rod]\nmodel = "planar"\n',
    "clamp in a winding": GOOD.replace(
        'type = "uniform"\nB = "5 mT"',
        'type = "coils"\ncoil = [ { type = "coil", radius = "20 mm", turns = 100, '
        'current = "1 A", axis = "z", winding = ["10 mm", "10 mm"], '
        'center = ["-20 mm", "0 mm", "0 mm"] } ]',
    ),
    "FEM too large": GOOD + '[models]\nrun = ["fem3d"]\n[fem]\nelements3d = [200, 4, 4]\n',
    "lambda too large": GOOD.replace('B = "5 mT"', 'B = "95 T"'),
}


@pytest.mark.parametrize("case", list(UNSOLVABLE))
def test_check_catches_what_run_would(tmp_path, capsys, no_solving, case):
    scene = write(tmp_path, UNSOLVABLE[case])
    assert main(["check", str(scene)]) == 2
    from_check = errors(capsys)
    assert main(["run", str(scene), "--out", str(tmp_path / "out")]) == 2
    from_run = errors(capsys)
    assert from_check == from_run
    assert len(from_check) == 2
    assert from_check[0].startswith(("field.", "fem."))
    assert from_check[1] == f"{scene}: the scene file with the problem above"
    assert not (tmp_path / "out").exists()


# -- the console script -------------------------------------------------------------------------
def console_script() -> list[str]:
    script = Path(sys.executable).with_name("coilrod")
    return [str(script)] if script.exists() else [sys.executable, "-m", "coilrod"]


def console(args: list[str], capsys, script: bool) -> tuple[int, str, str]:
    """Exit code, stdout and stderr of ``coilrod args``: through the installed console script
    in a new process (``script``), else through ``main`` in this one -- the same code, without
    the ~0.8 s of CPU a process costs to start (each test below runs its first case through
    the console script)."""
    if script:
        proc = subprocess.run(
            [*console_script(), *args], capture_output=True, text=True, timeout=300
        )
        return proc.returncode, proc.stdout, proc.stderr
    code = main(args)
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.mark.parametrize(
    ("text", "n_lines", "script"),
    [
        (THREE_MISTAKES, 3, True),
        # two numbers too large for any solve (reported together)
        (GOOD.replace("steps = 2", "steps = 1e20").replace('"40 mm"', '"1e300 m"'), 2, False),
    ],
)
def test_console_script_exit_2_one_line_per_problem(tmp_path, capsys, text, n_lines, script):
    scene = write(tmp_path, text)
    code, out, err = console(["run", str(scene), "--out", str(tmp_path / "out")], capsys, script)
    assert code == 2
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == n_lines + 1  # and the line naming the file
    assert all(line.startswith("coilrod: error: ") for line in lines)
    assert lines[-1].endswith(f"{scene}: the scene file with the {n_lines} problems above")
    assert out == ""


def test_console_script_bad_bytes_and_directory(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_bytes(b'name = "\x80"\n')
    for target, script in ((bad, True), (tmp_path, False)):
        code, _, err = console(["check", str(target)], capsys, script)
        assert code == 2
        assert "Traceback" not in err
        assert len(err.strip().splitlines()) == 1
        assert err.startswith(f"coilrod: error: {target}: ")


def test_integer_too_long_for_python(tmp_path, capsys):
    # tomllib raises a plain ValueError for integers beyond Python's 4300-digit limit
    path = write(tmp_path, GOOD.replace("steps = 2", "steps = 1" + "0" * 5000))
    assert main(["check", str(path)]) == 2
    (line,) = errors(capsys)
    assert line.startswith(f"{path}: not valid TOML (Exceeds the limit (4300 digits)")
