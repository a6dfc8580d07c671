"""A parameter study: the default example's accuracy for several k_sub (a loop over dicts).

    python examples/python/k_sub_study.py        (from the repository root, Python >= 3.11 for tomllib)
"""

import tomllib

import substep

with open("examples/default.toml", "rb") as f:
    base = tomllib.load(f)
for k_sub in (1, 2, 4, 8):
    base["substructure"]["substeps"] = k_sub
    s = substep.run(base).summary
    print(f"k_sub = {k_sub}: max displacement error {100 * s['reference']['max_displacement_error']:.3f} %")
