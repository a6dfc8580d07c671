"""Every Python example of the documentation runs: each ```python block of docs/*.md and the
README, and each script in examples/python/, as its own Python process in a scratch folder whose
`examples/` is the repository's (what a user sees after cloning). A block that is only a
fragment of a larger script is marked `<!-- fragment -->` on the line above it and skipped."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import ROOT

BLOCK = re.compile(r"(?P<before>[^\n]*)\n```python\n(?P<code>.*?)\n```", re.S)
DOCS = sorted((ROOT / "docs").glob("*.md")) + [ROOT / "README.md"]


def _blocks():
    out = []
    for doc in DOCS:
        text = doc.read_text()
        for m in BLOCK.finditer(text):
            if "<!-- fragment -->" in m["before"]:
                continue
            line = text[: m.start("code")].count("\n") + 1
            out.append(pytest.param(m["code"], id=f"{doc.name}:{line}"))
    for script in sorted((ROOT / "examples" / "python").glob("*.py")):
        out.append(pytest.param(script.read_text(), id=f"examples/python/{script.name}"))
    return out


def test_the_docs_have_python_examples():
    ids = [p.id for p in _blocks()]
    assert sum(i.startswith("python.md") for i in ids) >= 6, ids
    assert any(i.startswith("README.md") for i in ids)
    assert any(i.startswith("examples/python/") for i in ids)


@pytest.mark.parametrize("code", _blocks())
def test_a_documented_example_runs(code, tmp_path):
    if "tomllib" in code and sys.version_info < (3, 11):
        pytest.skip("the example reads TOML with tomllib (Python >= 3.11)")
    (tmp_path / "examples").symlink_to(ROOT / "examples")
    script = tmp_path / "example.py"
    # A block indented inside a list item is dedented as Python needs.
    lines = code.splitlines()
    indent = min((len(l) - len(l.lstrip()) for l in lines if l.strip()), default=0)
    script.write_text("\n".join(l[indent:] for l in lines) + "\n")
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT / "python"), env.get("PYTHONPATH", "")])
    proc = subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, f"{proc.stdout[-2000:]}\n{proc.stderr[-4000:]}"
