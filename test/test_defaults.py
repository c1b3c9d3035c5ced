"""One source for each default: the sessions' settings (alpha, hop, lookahead, blend, gap, follow,
foot lock, ground, conform, pipelined, seed spread) are written in runtime/defaults.py and nowhere
else in the package; every other place reads DEFAULTS."""

import re
from pathlib import Path

from motion_style_ros.runtime.defaults import DEFAULTS

PACKAGE = Path(__file__).resolve().parents[1] / "motion_style_ros"


def literal_defaults(text: str, name: str, value) -> list[str]:
    """Where ``text`` writes ``value`` as ``name``'s default: a keyword default or argument, a
    parameter table entry, a command-line option's default, a dict entry."""
    literal = re.escape(repr(value))
    patterns = [rf"\b{name}\s*(?::\s*[^=,)\n]+)?=\s*{literal}(?![\w.])",
                rf'Parameter\("{name}",\s*{literal}(?![\w.])',
                rf'"--{name.replace("_", "-")}"[^\n]*default={literal}(?![\w.])',
                rf'"{name}":\s*{literal}(?![\w.])']
    return [m.group(0) for pattern in patterns for m in re.finditer(pattern, text)]


def test_the_scan_finds_a_default_written_again():
    assert literal_defaults("def run(self, alpha: float = 1.0):", "alpha", 1.0)
    assert literal_defaults('p.add_argument("--seed-spread", type=float, default=1.0)', "seed_spread", 1.0)
    assert not literal_defaults('alpha: float = DEFAULTS["alpha"]', "alpha", 1.0)


def test_no_setting_default_is_written_outside_runtime_defaults():
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.name == "defaults.py" and path.parent.name == "runtime":
            continue
        text = path.read_text()
        for name, value in DEFAULTS.items():
            found += [f"{path.relative_to(PACKAGE)}: {hit}" for hit in literal_defaults(text, name, value)]
    assert not found, "\n".join(found)
