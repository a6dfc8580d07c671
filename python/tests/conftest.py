"""Shared fixtures: the repository root and the `substep` binary built by cargo (the CLI the
Python results are compared with)."""

import os
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def root() -> Path:
    return ROOT


@pytest.fixture(scope="session")
def cli() -> Path:
    path = Path(os.environ.get("SUBSTEP_BIN", ROOT / "target" / "release" / "substep"))
    if not path.exists():
        pytest.fail(f"{path}: the substep binary is missing (cargo build --release)")
    return path


def run_cli(cli: Path, *args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    """The CLI with `args`, bounded in time, output captured as text."""
    return subprocess.run([str(cli), *args], cwd=cwd, capture_output=True, text=True, timeout=300)


def read_csv_exact(path) -> "pandas.DataFrame":
    """A CSV file of numbers as a float DataFrame, each field parsed by Python's correctly
    rounded `float` (independent of the pandas version's parser)."""
    import csv

    import pandas as pd

    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    header, body = rows[0], rows[1:]
    return pd.DataFrame([[float(x) for x in r] for r in body], columns=header, dtype=float)


#: examples/frame3d_reduced.toml (101 388 DOFs, 13 s to reduce, 2 min with its check) scaled (the list of
#: crates/substep/tests/common/frame3d_scaled.rs) down to 120 DOFs; benches/frame3d_reduced.sh runs the real one.
FRAME3D_SCALING = [
    ("bays = 30\n", "bays = 2\n"),
    ("bays_y = 15\n", "bays_y = 2\n"),
    ("stories = 68\n", "stories = 4\n"),
    ("modes = 40\n", "modes = 12\n"),
    ("keep = [99898]", "keep = [91]"),  # floor 4's U_x with rigid floors: 3 (3 + 3 * 9) + 1
    ("stiffness = 5.0e7 ", "stiffness = 5.0e5 "),  # the damper scaled with the floor mass
    ("damping = 5.0e6 ", "damping = 5.0e4 "),
]


def scaled_frame3d(directory: Path) -> Path:
    """examples/frame3d_reduced.toml scaled down (FRAME3D_SCALING), written into `directory`
    with its record path made absolute; returns the file."""
    text = (ROOT / "examples" / "frame3d_reduced.toml").read_text()
    for old, new in FRAME3D_SCALING + [('"records/', f'"{ROOT}/examples/records/')]:
        assert old in text, f"frame3d_reduced.toml changed ({old!r}): adapt FRAME3D_SCALING"
        text = text.replace(old, new)
    path = directory / "frame3d_reduced.toml"
    path.write_text(text)
    return path

