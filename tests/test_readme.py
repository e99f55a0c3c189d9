"""The README's library example runs as written, and its numbers hold up."""

import re
from pathlib import Path

import numpy as np
import pytest

README = Path(__file__).resolve().parents[1] / "README.md"


def test_library_example_runs(capsys):
    text = README.read_text(encoding="utf-8")
    block = re.search(r"```python\n(.*?)```", text, re.S).group(1)
    namespace: dict = {}
    exec(compile(block, "README.md", "exec"), namespace)  # noqa: S102
    L = namespace["rod"].length
    real, ideal, fem = namespace["real"], namespace["ideal"], namespace["fem"]
    # the real pair moves the tip (R = 2 L: more than 1% of L) and the FEM agrees with the rod
    assert np.linalg.norm(real.tip[-1] - ideal.tip[-1]) > 0.01 * L
    assert np.linalg.norm(fem.tip[-1] - real.tip[-1]) < 0.01 * L
    assert "within 1% of ideal" in capsys.readouterr().out


def test_design_example_runs(capsys):
    """The design example (run on its own, as every README block) gives exact
    sensitivities: the current derivative against a central difference of two solves."""
    import coilrod

    text = README.read_text(encoding="utf-8")
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    design = next(b for b in blocks if "sensitivities(res" in b)
    # the workspace line runs on a 12 x 4 grid refined once (the README's 36 x 8 refined six
    # times costs ~6 s of CPU and nothing below checks its area; test_workspace*.py check
    # the workspace at its grids): the same call, fewer solves
    line = "workspace(rod, b_max=0.012, directions=36, magnitudes=8)"
    assert design.count(line) == 1
    design = design.replace(
        line, "workspace(rod, b_max=0.012, directions=12, magnitudes=4, refine=1)"
    )
    namespace: dict = {}
    exec(compile(design, "README.md", "exec"), namespace)  # noqa: S102
    # the polygon it returns encloses its area (shoelace against the shapely union)
    x, y = namespace["ws"].boundary.T
    shoelace = 0.5 * abs(np.dot(x, np.roll(y, 1)) - np.dot(y, np.roll(x, 1)))
    assert shoelace == pytest.approx(namespace["ws"].area, rel=1e-9)
    # the ratio the README states in its comment is the one printed
    stated = re.search(r'print\(f"\{best.ratio:.2f\}"\)\s+# ([0-9.]+) ', design).group(1)
    assert capsys.readouterr().out.strip().endswith(stated)
    best = namespace["best"]
    assert best.ratio == pytest.approx(best.area / best.uniform_area, rel=1e-12)
    rod, pair, scales, d = (namespace[k] for k in ("rod", "pair", "scales", "d"))
    h = 1e-3
    tips = [
        coilrod.solve_rod(rod, pair.with_current(pair.current + s * h), scales, tol=1e-12).tip[-1]
        for s in (1, -1)
    ]
    fd = (tips[0] - tips[1]) / (2 * h)
    np.testing.assert_allclose(d["currents"].tip[0], fd, rtol=1e-5, atol=1e-9 * np.abs(fd).max())
    assert d["angles"].tip.shape == (4, 3)


def test_control_example_runs():
    """The steering example lands on its target: checked by solve_bvp with its currents."""
    from rod_bvp_reference import bvp_tip_continued

    text = README.read_text(encoding="utf-8")
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    control = next(b for b in blocks if "solve_currents(" in b)
    namespace: dict = {}
    exec(compile(control, "README.md", "exec"), namespace)  # noqa: S102
    rod, system, out, ideal = (namespace[k] for k in ("rod", "system", "out", "ideal"))
    field = system.with_currents(out.currents)
    tip = bvp_tip_continued(rod, field, np.linspace(0.1, 1.0, 10))
    np.testing.assert_allclose(tip, [0.029, 0.025], atol=1e-6 * rod.length)
    tip_ideal = bvp_tip_continued(
        rod, system.with_currents(ideal.currents), np.linspace(0.1, 1.0, 10)
    )
    assert abs(np.linalg.norm(tip_ideal - [0.029, 0.025]) - ideal.miss) <= 1e-6 * rod.length


def test_quick_start_test_command_is_what_ci_runs():
    text = README.read_text(encoding="utf-8")
    quick = re.search(r"## Quick start\n\n```bash\n(.*?)```", text, re.S).group(1).splitlines()
    assert len(quick) == 2
    ci = (README.parent / ".ci" / "run").read_text()
    test_command = quick[1].split("&&")[-1].strip()
    assert test_command == "python -m pytest"
    assert ci.strip().splitlines()[-1].strip() == test_command
    assert 'pip install -e ".[test]"' in ci


def _block(marker):
    text = README.read_text(encoding="utf-8")
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    namespace: dict = {}  # every block runs on its own: no names from an earlier block
    exec(compile(next(b for b in blocks if marker in b), "README.md", "exec"), namespace)  # noqa: S102
    return namespace


def test_spatial_example_runs():
    """The 3D example: out-of-plane field and elevation take the spatial model; the frames
    are rotations."""
    ns = _block("clamp_rotation=")
    res = ns["res"]
    assert res.model == "spatial"
    R = res.frames(9)
    assert np.abs(np.swapaxes(R, -1, -2) @ R - np.eye(3)).max() < 1e-12
    assert abs(res.tip[-1, 2]) > 1e-4


def test_contact_example_runs():
    """The contact example: the 2 mm rod's surface rests on the wall (8 mm; its axis at 7 mm)
    with a positive force on it, and the insertion gets round the bend without penetrating
    the wall; the largest wall force is the largest magnitude."""
    ns = _block("obstacles=[wall]")
    res, ins = ns["res"], ns["ins"]
    L = ns["rod"].length
    assert res.gaps(1).min() >= -1e-9 * L
    assert abs(res.tip[1, 1] - (0.008 - 0.5 * ns["rod"].section.diameter)) < 1e-9
    assert ins.wall_force_magnitude.max() == np.linalg.norm(ins.wall_force, axis=1).max()
    assert res.obstacle_forces(1)[0][1] > 0
    assert ins.min_gap.min() >= -1e-6 * L
    assert ins.tip[-1, 1] > 0.02


def test_every_python_block_stands_alone():
    """Each README block defines or imports every name it uses (a reader copies one block
    into a fresh session): checked statically, without running the blocks again."""
    import ast
    import builtins

    text = README.read_text(encoding="utf-8")
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert len(blocks) >= 5
    for i, block in enumerate(blocks):
        tree = ast.parse(block)
        bound = set(dir(builtins))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import | ast.ImportFrom):
                bound |= {(a.asname or a.name).split(".")[0] for a in node.names}
            elif isinstance(node, ast.FunctionDef):
                bound.add(node.name)
                bound |= {a.arg for a in node.args.args}
            elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
                bound.add(node.id)
            elif isinstance(node, ast.arg):
                bound.add(node.arg)
        used = {
            n.id for n in ast.walk(tree) if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Load)
        }
        assert used <= bound, f"README block {i} uses {sorted(used - bound)} without defining them"
