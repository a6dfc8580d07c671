"""Bad input from Python (issue 41): wrong types, unknown keys, values TOML cannot hold, paths
that cannot be written. Each raises ``ConfigError`` naming the key path or the path, within a
few seconds (an alarm fails a call that hangs), and never crashes the interpreter."""

import copy
import math
import os
import signal

import numpy as np
import pytest

import substep

tomllib = pytest.importorskip("tomllib")


@pytest.fixture
def base(root):
    """examples/default.toml as a dict, shortened to 1 s."""
    config = tomllib.loads((root / "examples" / "default.toml").read_text())
    config["ground_motion"]["duration"] = 1.0
    config.pop("output", None)
    return config


@pytest.fixture(autouse=True)
def no_hang():
    """Every call of a test here must return within 30 s (SIGALRM; the run loop looks at
    Python's signals every 100 ms)."""

    def fail(*_):
        raise TimeoutError("a bad-input call did not return within 30 s")

    old = signal.signal(signal.SIGALRM, fail)
    signal.alarm(30)
    yield
    signal.alarm(0)
    signal.signal(signal.SIGALRM, old)


def with_value(config, path, value):
    c = copy.deepcopy(config)
    *head, last = path
    node = c
    for k in head:
        node = node[k]
    node[last] = value
    return c


# (where in the dict, the value, what the message must say after "<dict>: ")
WRONG_VALUES = [
    (("integrator", "dt"), "fast", "integrator.dt"),
    (("integrator", "dt"), True, "integrator.dt"),
    (("integrator", "dt"), math.nan, "integrator.dt"),
    (("integrator", "dt"), -0.01, "integrator.dt"),
    (("integrator", "dt"), [0.01], "integrator.dt"),
    (("integrator", "dt"), None, "integrator.dt"),
    (("integrator", "dt"), {1, 2}, "integrator.dt"),
    (("integrator", "dt"), object(), "integrator.dt"),
    (("structure", "sdof", "mass"), "heavy", "structure.sdof.mass"),
    (("structure", "sdof", "mass"), 0.0, "structure.sdof.mass"),
    (("substructure", "substeps"), 2.5, "substructure.substeps"),
    (("substructure", "substeps"), -1, "substructure.substeps"),
    (("substructure", "coupling_dofs"), [7], "substructure.coupling_dofs"),
    (("substructure", "coupling_dofs"), "1", "substructure.coupling_dofs"),
    (("substructure", "specimen"), {"kind": "linear_sdof"}, "substructure.specimen"),
    (("substructure", "actuator", "kind"), "magic", "substructure.actuator"),
    (("ground_motion", "generator"), "earthquake", "ground_motion"),
    (("integrator", "scheme"), "rk4", "integrator.scheme"),
    (("integrator", "dtt"), 0.01, "integrator.dtt"),
    (("bogus",), {"x": 1}, "bogus"),
]


@pytest.mark.parametrize("path,value,key", WRONG_VALUES, ids=[f"{'.'.join(p)}={v!r}" for p, v, _ in WRONG_VALUES])
def test_a_wrong_value_raises_config_error_naming_its_key(base, path, value, key):
    with pytest.raises(substep.ConfigError) as e:
        substep.run(with_value(base, path, value))
    message = str(e.value)
    assert message.startswith("<dict>: "), message
    assert key in message, message
    assert "\n" not in message, message


def test_a_key_that_is_not_a_string_is_named(base):
    c = copy.deepcopy(base)
    c["integrator"][3] = 1
    with pytest.raises(substep.ConfigError, match=r"^<dict>: integrator: the key 3 is not a string"):
        substep.run(c)


def test_a_config_of_the_wrong_type_is_a_config_error_and_a_type_error():
    for value in (42, 4.2, None, b"[structure]", ["a"]):
        with pytest.raises(substep.ConfigError, match=r"^config: must be a path, a TOML string or a dict") as e:
            substep.run(value)
        assert isinstance(e.value, TypeError)


def test_numpy_values_are_numbers(base):
    """numpy scalars and arrays in a dict are the numbers they hold (no error, the same run)."""
    plain = substep.run(base)
    c = copy.deepcopy(base)
    c["integrator"]["dt"] = np.float64(0.01)
    c["substructure"]["substeps"] = np.int64(4)
    c["substructure"]["coupling_dofs"] = np.array([1])
    with_numpy = substep.run(c)
    np.testing.assert_array_equal(with_numpy.history.values, plain.history.values)


def test_a_missing_or_unreadable_config_file_is_named(tmp_path):
    with pytest.raises(substep.ConfigError, match="nothing_here.toml"):
        substep.run(str(tmp_path / "nothing_here.toml"))
    with pytest.raises(substep.ConfigError, match=str(tmp_path)):
        substep.run(tmp_path)  # a directory, not a file
    binary = tmp_path / "binary.toml"
    binary.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(substep.ConfigError, match="binary.toml"):
        substep.run(str(binary))


def test_a_path_that_cannot_be_written_raises_config_error_naming_it(base, tmp_path):
    result = substep.run(base)
    blocker = tmp_path / "a_file"
    blocker.write_text("not a directory")
    for target in (blocker / "out", blocker / "out.csv", blocker / "x.h5", blocker / "x.mat"):
        with pytest.raises(substep.ConfigError) as e:
            result.save(target)
        assert isinstance(e.value, OSError)
        assert str(target) in str(e.value), str(e.value)
        assert "cannot write" in str(e.value)
    # Nothing was written next to the blocker, and the file is unchanged.
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file"]
    assert blocker.read_text() == "not a directory"
    if os.geteuid() != 0:
        locked = tmp_path / "locked"
        locked.mkdir()
        locked.chmod(0o500)
        try:
            with pytest.raises(substep.ConfigError, match="locked"):
                result.save(locked / "history.csv")
        finally:
            locked.chmod(0o700)
    # An unknown suffix names it, as before.
    with pytest.raises(substep.ConfigError, match=r"\.xlsx"):
        result.save(tmp_path / "x.xlsx")


def test_a_toml_string_with_a_syntax_error_names_the_line():
    with pytest.raises(substep.ConfigError, match=r"^<string>: line 2"):
        substep.run("[structure.sdof]\nmass = = 1\n")
