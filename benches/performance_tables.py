#!/usr/bin/env python3
"""Write the measured tables of docs/performance.md from docs/performance.json (the output of
benches/performance.sh): everything between the two `harness` markers is replaced, so the figures
in the document are exactly the harness's. Usage: python3 benches/performance_tables.py
[docs/performance.json [docs/performance.md]]"""
import json
import sys

BEGIN = "<!-- harness: begin (benches/performance_tables.py writes this part) -->"
END = "<!-- harness: end -->"


def us(x):
    if x is None:
        return "—"
    return f"{x:,.0f}".replace(",", " ") if x >= 100 else f"{x:.1f}"


def count(n):
    return f"{n:,}".replace(",", " ")


def mib(b):
    return f"{b / 2**20:.1f}"


def sweep_table(runs, title, baseline=None):
    out = [title, ""]
    base = {r["dofs"]: r for r in (baseline or {}).get("runs", [])}
    head = "| DOFs | layout | solver | MB per solve | floor µs | median µs | p99 µs | CPU median µs | × real time | peak RSS MiB |"
    if base:
        head += " before µs (same run) | now / before |"
    out.append(head)
    out.append("|" + "---:|" * (head.count("|") - 1))
    for r in runs:
        row = (
            f"| {count(r['dofs'])} | {r.get('layout', '')} | {r['solver']} | {r.get('solve_bytes', 0) / 1e6:.1f} "
            f"| {us(r.get('solve_floor_us'))} | {us(r['us_per_step_median'])} | {us(r['us_per_step_p99'])} "
            f"| {us(r.get('cpu_us_per_step_median'))} | {r['realtime_ratio']:.4f} | {mib(r['peak_rss_bytes'])} |"
        )
        if base:
            b = base.get(r["dofs"])
            if b:
                row += f" {us(b['us_per_step_median'])} | {r['us_per_step_median'] / b['us_per_step_median']:.3f} |"
            else:
                row += " — | — |"
        out.append(row)
    return out + [""]


def compare_table(c, title):
    m = c["substep_cpu_us_per_step"]
    two = " (two cores)" if c.get("substep_second_core") else " (one core)"
    out = [
        title,
        "",
        f"{count(c['dofs'])} DOFs ({c.get('layout', '')}); substep: {c['substep_solver']}{two}, "
        f"{c['substep_solve_bytes'] / 1e6:.1f} MB per solve; CPU time per step over {c['rounds']} interleaved "
        f"rounds of {c['batches']} batches of {c['batch_steps']} steps (median of the batches per round; "
        "median and min–max over the rounds); agreement = largest difference of the roof response over "
        f"{c['check_steps']} steps from rest, relative to its peak.",
        "",
        "| tool | CPU µs per step, median (min–max) | values in the factor | agreement | substep is … × faster (monolithic / full substructure step) |",
        "|---|---:|---:|---:|---:|",
        f"| substep monolithic step | {us(m['median'])} ({us(m['min'])} – {us(m['max'])}) | | | |",
        f"| substep full substructure step, k_sub = 10 | {us(c['substep_substructure_cpu_us_per_step'])} "
        f"(wall p99 {us(c['substep_substructure_p99_us'])}) | | | |",
    ]
    for t in c["tools"]:
        if t["status"] != "agreed":
            out.append(f"| {t['tool']} | {t['status']}: {t.get('reason') or ''} | | | |")
            continue
        s = t["cpu_us_per_step"]
        nnz = t.get("detail", {}).get("factor_nnz")
        out.append(
            f"| {t['tool']} | {us(s['median'])} ({us(s['min'])} – {us(s['max'])}) | "
            f"{nnz / 1e6:.2f} M | {t['agreement']:.1e} | "
            f"**{t['ratio_to_monolithic']:.2f}** / **{t['ratio_to_substructure_step']:.2f}** |"
            if nnz
            else f"| {t['tool']} | {us(s['median'])} ({us(s['min'])} – {us(s['max'])}) | | {t['agreement']:.1e} | "
            f"**{t['ratio_to_monolithic']:.2f}** / **{t['ratio_to_substructure_step']:.2f}** |"
        )
    return out + [""]


def main():
    src = sys.argv[1] if len(sys.argv) > 1 else "docs/performance.json"
    doc = sys.argv[2] if len(sys.argv) > 2 else "docs/performance.md"
    d = json.load(open(src))
    mach = d["machine"]
    lines = [
        BEGIN,
        "",
        f"Measured by `{d['command']}` on {mach['cpu']} ({mach['cores']} cores, kernel {mach['kernel']}); "
        f"load average before {mach['load_average_before']}, after {mach['load_average_after']}"
        + (f"; {d['date']}" if "date" in d else "")
        + ". The floor is the bytes of the factor read per solve over the streaming read bandwidth "
        "the benchmark measures in the same process (`read_bandwidth_gbs`, one core).",
        "",
    ]
    lines += sweep_table(d["chain_sweep"]["runs"], "**Chain**, `k_sub = 10`:", d.get("chain_sweep_baseline"))
    lines += sweep_table(d["frame_sweep"]["runs"], "**2-D frame**, one core:")
    lines += sweep_table(d["frame_sweep_two_cores"]["runs"], "**2-D frame**, `--two-cores`:")
    for key, title in [
        ("frame3d_1e4", "**3-D frame**, 10⁴ DOFs:"),
        ("frame3d_1e5", "**3-D frame**, 10⁵ DOFs, one core:"),
        ("frame3d_1e5_two_cores", "**3-D frame**, 10⁵ DOFs, `--two-cores`:"),
    ]:
        if key in d:
            lines += sweep_table([d[key]], title)
    for key, title in [
        ("compare_5000_dof_chain", "**Comparison, 5000-DOF chain, one core** (OpenSees, SciPy)"),
        ("compare_frame_1e4", "**Comparison, 10⁴ 2-D frame, one core**"),
        ("compare_frame_1e4_two_cores", "**Comparison, 10⁴ 2-D frame, substep on two cores**"),
        ("compare_frame_1e5", "**Comparison, 10⁵ 2-D frame, one core**"),
        ("compare_frame_1e5_two_cores", "**Comparison, 10⁵ 2-D frame, substep on two cores**"),
        ("compare_frame3d_1e4", "**Comparison, 10⁴ 3-D frame, one core**"),
    ]:
        if key in d:
            lines += compare_table(d[key], title)
    lines.append(END)
    text = open(doc).read()
    if BEGIN not in text or END not in text:
        sys.exit(f"{doc}: the harness markers are missing")
    head, rest = text.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    open(doc, "w").write(head + "\n".join(lines) + tail)
    print(f"wrote the measured tables of {doc} from {src}", file=sys.stderr)


if __name__ == "__main__":
    main()
