"""The minimal valid scene the scene tests start from, and a way to change its keys."""

import copy

BASE = {
    "name": "test",
    "robot": {
        "length": "40 mm",
        "diameter": "2 mm",
        "youngs_modulus": "1 MPa",
        "magnetization": {"preset": "M1"},
    },
    "field": {"type": "uniform", "B": "5 mT", "direction": "y"},
    "load": {"steps": 4},
    "models": {"run": ["rod"]},
}


def scene_with(**changes):
    """A copy of BASE with keys replaced, nested keys written ``robot__length`` (None removes
    the key)."""
    data = copy.deepcopy(BASE)
    for dotted, value in changes.items():
        *parents, last = dotted.split("__")
        node = data
        for p in parents:
            node = node.setdefault(p, {})
        if value is None:
            node.pop(last, None)
        else:
            node[last] = value
    return data
