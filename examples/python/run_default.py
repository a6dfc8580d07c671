"""Run the default example from Python and compare the test with its exact reference.

    python examples/python/run_default.py        (from the repository root, with the package installed)
"""

import substep

r = substep.run("examples/default.toml")
print(r)
df = r.to_pandas()
err = (df.u1 - df.uref1).abs().max() / df.uref1.abs().max()
print(f"max |u - u_ref| / max |u_ref| = {100 * err:.3f} %")
assert err == r.summary["reference"]["max_displacement_error"]
print("written:", ", ".join(r.save("results/python")))
