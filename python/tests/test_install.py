"""`pip install ./python` needs nothing but Rust and Python (issue 41): the compiled module links
no library outside the C runtime (the Python ABI comes from the interpreter that loads it), and
no crate in the package's build graph links a system library. `scripts/install-check` (run by
.ci/run) does the install itself in a fresh environment with pkg-config hidden."""

import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

import substep

# The C runtime and the dynamic loader: what every Rust cdylib on glibc links.
RUNTIME = {"linux-vdso.so.1", "libc.so.6", "libm.so.6", "libgcc_s.so.1", "libpthread.so.0",
           "libdl.so.2", "librt.so.1", "ld-linux-x86-64.so.2", "ld-linux-aarch64.so.1"}
# `links` keys of crates that link nothing from the system: the interpreter's own symbols
# (pyo3), and rayon's marker against two copies of its thread pool.
LINKS_WITHOUT_SYSTEM_LIBRARY = {"python", "pyo3-python", "rayon-core"}


def linked_libraries(path: Path) -> set:
    out = subprocess.run(["ldd", str(path)], capture_output=True, text=True, timeout=60, check=True).stdout
    names = set()
    for line in out.splitlines():
        word = line.split()[0] if line.split() else ""
        names.add(os.path.basename(word))
    names.discard("")
    return names


def test_compiled_module_links_only_the_c_runtime():
    if shutil.which("ldd") is None:
        pytest.skip("ldd not found (not a glibc system)")
    module = Path(substep._substep.__file__)
    libraries = linked_libraries(module)
    assert "libc.so.6" in libraries, libraries  # the parse found the runtime, so it can find others
    assert libraries <= RUNTIME, f"{module} links {sorted(libraries - RUNTIME)}"


def test_ldd_parse_sees_a_system_library():
    # The check above would pass vacuously if the parse missed libraries: it sees libpython or
    # the interpreter's other libraries in a binary that links more than the runtime.
    if shutil.which("ldd") is None:
        pytest.skip("ldd not found (not a glibc system)")
    candidates = [Path(p) for p in ("/usr/bin/openssl", "/usr/bin/curl", "/usr/bin/python3")]
    linked = next((linked_libraries(p) for p in candidates if p.exists() and linked_libraries(p) - RUNTIME), None)
    if linked is None:
        pytest.skip("no binary on this machine links a library outside the C runtime")
    assert linked - RUNTIME


def test_no_crate_of_the_package_links_a_system_library(root):
    cargo = shutil.which("cargo")
    if cargo is None:
        pytest.skip("cargo not on PATH")
    host = next(line.split()[1] for line in subprocess.run(
        ["rustc", "-vV"], capture_output=True, text=True, timeout=60, check=True).stdout.splitlines()
        if line.startswith("host:"))
    proc = subprocess.run(
        [cargo, "metadata", "--format-version", "1", "--locked", "--filter-platform", host,
         "--manifest-path", str(root / "python" / "Cargo.toml")],
        capture_output=True, text=True, timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    meta = json.loads(proc.stdout)
    # Only the packages the Python extension's build reaches, not the whole workspace.
    nodes = {n["id"]: n for n in meta["resolve"]["nodes"]}
    by_id = {p["id"]: p for p in meta["packages"]}
    start = next(p["id"] for p in meta["packages"] if p["name"] == "substep-python")
    seen, todo = set(), [start]
    while todo:
        node = todo.pop()
        if node in seen:
            continue
        seen.add(node)
        todo.extend(d["pkg"] for d in nodes[node]["deps"]
                    if any(k["kind"] in (None, "build") for k in d["dep_kinds"]))
    links = {by_id[i]["name"]: by_id[i]["links"] for i in seen if by_id[i].get("links")}
    assert "substep" in {by_id[i]["name"] for i in seen}
    assert "hdf5-pure" in {by_id[i]["name"] for i in seen}
    assert set(links.values()) <= LINKS_WITHOUT_SYSTEM_LIBRARY, links
