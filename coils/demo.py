"""``python -m coils.demo [OUTDIR]``: real Helmholtz and Maxwell pairs against their ideal fields.

Prints centre values against the closed forms and the uniformity regions, and writes field maps
(PNG) to OUTDIR (default ``./coils-demo``).
"""

from __future__ import annotations

import sys
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    out = Path(argv[0] if argv else "coils-demo")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:  # a file there, no permission: one line, before any work
        print(
            f"coils.demo: error: cannot create the folder {out} ({exc.strerror or exc})",
            file=sys.stderr,
        )
        return 2
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from . import HelmholtzPair, MaxwellPair
    from ._files import replacing
    from .plot import plot_field_map
    from .region import uniformity

    radius, turns, current = 0.1, 200, 2.0
    helm = HelmholtzPair(radius, turns, current, axis="y")
    maxw = MaxwellPair(radius, turns, current, axis="y")
    b = helm.B([[0, 0, 0]])[0, 1]
    g = maxw.gradient([[0, 0, 0]])[0, 1, 1]
    print(f"Helmholtz pair R = {radius} m, N = {turns}, I = {current} A")
    print(f"  centre field {1e3 * b:.6f} mT   closed form {1e3 * helm.center_field:.6f} mT")
    print("  " + str(uniformity(helm, 0.01)).replace("\n", "\n  "))
    print("Maxwell pair, same coils at spacing sqrt(3) R, opposed currents")
    print(f"  centre gradient {1e3 * g:.6f} mT/m closed form {1e3 * maxw.center_gradient:.6f} mT/m")
    print("  " + str(uniformity(maxw, 0.01)).replace("\n", "\n  "))
    for name, coil in (("helmholtz", helm), ("maxwell", maxw)):
        fig, ax = plt.subplots(figsize=(6, 5))
        plot_field_map(coil, "xy", half_width=1.2 * radius, ax=ax)
        path = out / f"{name}_field_map.png"
        try:
            with replacing(path) as tmp:  # whole or not at all
                fig.savefig(tmp, dpi=120, bbox_inches="tight")
        except OSError as exc:
            print(f"coils.demo: error: {exc}", file=sys.stderr)
            return 2
        finally:
            plt.close(fig)
        print(f"  wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
