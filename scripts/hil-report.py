#!/usr/bin/python3
"""HIL replay report (docs/hil.md): one self-contained HTML page per case with PNG plots, an
index page and a JSON summary. Run by `palpa hil report -o DIR`, which replays the cases first;
it can also be run by hand on a results directory:

    /usr/bin/python3 scripts/hil-report.py --results build/hil-work/results/realtime -o REPORT_DIR

Inputs per case (results/<mode>/<case>/): result.json (palpa hil's metrics and palpad's summary),
series.csv (per tick: t_s, |f| N, analytic |f| N, spring |X_h - X_p| m, phi(HIP) m, phi(proxy) m),
timing.csv (per tick wake-up latency and compute time, ns; paced runs, when palpad wrote it).
Plots use matplotlib (Debian python3-matplotlib) with the Agg backend; pages embed the PNGs as
data: URIs, so they open offline from anywhere.
"""
import argparse
import base64
import html
import io
import json
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def load_series(path):
    if not os.path.exists(path):
        return None
    data = np.genfromtxt(path, delimiter=",", names=True)
    return np.atleast_1d(data)


def load_timing(path):
    if not os.path.exists(path):
        return None
    data = np.genfromtxt(path, delimiter=",", names=True)
    return np.atleast_1d(data)


def png(fig):
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def force_plot(name, s, result):
    analytic = "analytic" in result and not np.all(np.isnan(s["analytic_n"]))
    if analytic:
        fig, (ax, ax_err) = plt.subplots(2, 1, figsize=(9, 5.2), sharex=True, gridspec_kw={"height_ratios": [3, 1.3]})
    else:
        fig, ax = plt.subplots(figsize=(9, 3.6))
    ax.plot(s["t_s"], s["force_n"], color="tab:blue", lw=1.2, label="rendered |f| (palpad)")
    if analytic:
        ax.plot(s["t_s"], s["analytic_n"], color="tab:red", lw=1.0, ls="--", label="analytic k·penetration (sphere)")
        err = 1e3 * (s["force_n"] - s["analytic_n"])
        ax_err.plot(s["t_s"], err, color="tab:purple", lw=0.8)
        a = result["analytic"]
        ax_err.set_ylabel("rendered − analytic (mN)", fontsize=8)
        ax_err.set_title(f"RMS error {a['rms_error_pct']:.3f} % of peak, direction RMS {a['rms_angle_deg']:.3f}°",
                         fontsize=9)
        ax_err.grid(alpha=0.3)
        ax_err.set_xlabel("time (s)")
    else:
        ax.set_xlabel("time (s)")
    if np.nanmax(s["force_n"]) > 0.5 * result["max_force_n"]:
        ax.axhline(result["max_force_n"], color="0.6", lw=0.8, ls=":", label="force clamp")
    ax.set_ylabel("force magnitude (N)")
    ax.set_title(f"{name}: force magnitude vs time")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize=8)
    return png(fig)


def penetration_plot(name, s):
    fig, ax = plt.subplots(figsize=(9, 3.6))
    ax.plot(s["t_s"], 1e3 * np.maximum(-s["phi_hip_m"], 0), color="tab:orange", lw=1.2,
            label="HIP depth −φ(HIP) (saturates at the band)")
    ax.plot(s["t_s"], 1e3 * s["spring_m"], color="tab:blue", lw=1.0, label="spring |X_h − X_p|")
    ax.plot(s["t_s"], 1e3 * np.maximum(-s["phi_proxy_m"], 0), color="tab:green", lw=1.0,
            label="proxy depth −φ(proxy) (≈ 0: the proxy stays outside)")
    if "analytic_depth_m" in s.dtype.names and not np.all(np.isnan(s["analytic_depth_m"])):
        ax.plot(s["t_s"], 1e3 * s["analytic_depth_m"], color="tab:red", lw=0.9, ls="--", label="analytic HIP depth")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("penetration (mm)")
    ax.set_title(f"{name}: proxy vs HIP penetration")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    return png(fig)


def percentiles(x):
    x = np.sort(np.asarray(x, dtype=float))
    if x.size == 0:
        return None
    rank = lambda q: x[max(0, int(np.ceil(q * x.size)) - 1)]  # nearest rank
    return {"p50": rank(0.5), "p99": rank(0.99), "p999": rank(0.999), "max": x[-1], "count": int(x.size)}


def latency_plot(name, timing, mode):
    series = [("compute_ns", "compute", "tab:blue")]
    if mode == "realtime":
        series = [("wake_ns", "wake-up latency", "tab:orange"), ("compute_ns", "compute", "tab:blue"),
                  ("total_ns", "total", "tab:purple")]
    fig, ax = plt.subplots(figsize=(9, 3.6))
    stats = {}
    hi, lo = 1.0, 1e9
    for col, _, _ in series:
        v = timing[col][timing[col] > 0] / 1e3
        if v.size:
            hi, lo = max(hi, v.max()), min(lo, v.min())
    lo = min(lo, hi / 10) / 1.5
    bins = np.logspace(np.log10(lo), np.log10(hi * 1.2), 80)
    for col, label, colour in series:
        v = timing[col][timing[col] >= 0] / 1e3  # µs
        if v.size == 0:
            continue
        p = percentiles(v)
        stats[label] = p
        ax.hist(np.maximum(v, lo), bins=bins, histtype="step", lw=1.3, color=colour,
                label=f"{label}: p50 {p['p50']:.1f}, p99 {p['p99']:.1f}, p99.9 {p['p999']:.1f}, max {p['max']:.1f} µs")
        for q, ls in (("p50", ":"), ("p99", "--"), ("p999", "-."), ("max", "-")):
            ax.axvline(max(p[q], lo), color=colour, lw=0.7, ls=ls, alpha=0.7)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("µs per tick (log)")
    ax.set_ylabel("ticks (log)")
    ax.set_title(f"{name}: latency histogram ({mode}); lines at p50 ··· p99 - - p99.9 -· max —")
    ax.grid(alpha=0.3, which="both")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.2), fontsize=8, frameon=False)
    return png(fig), stats


def row(k, v):
    return f"<tr><th>{html.escape(str(k))}</th><td>{html.escape(str(v))}</td></tr>"


def page(name, result, images, lat):
    summ = result.get("summary") or {}
    rows = [
        row("verdict", result["verdict"]),
        row("mode", result["mode"]),
        row("device", result["device"] + " — " + result["why"]),
        row("field / trace", f"{result['field']} / {result['trace']}"),
        row("k, clamp, rate", f"{result['k_n_per_m']} N/m, {result['max_force_n']} N, {result['rate_hz']} Hz"),
        row("palpad exit", result["exit_code"]),
        row("ticks (in contact)", f"{result['ticks']} ({result['contact_ticks']})"),
        row("max |f|", f"{result['max_force_n_seen']:.4f} N"),
        row("max force step", f"{result['max_slope_n']:.4f} N/tick (limit {result['slope_limit_n']:.4f})"),
        row("min φ(proxy)", f"{result['min_proxy_phi_voxels']:.4f} voxel"),
        row("passivity", f"E = {result['energy_j']:.3g} J, min margin {result['min_passivity_margin_j']:.3g} J"),
        row("overruns", summ.get("overruns", "-")),
        row("real-time", ("yes" if summ.get("realtime") else "NO: " + str(summ.get("rt_refused", "")))
            if result["mode"] == "realtime" else "not requested (fast)"),
        row("wall time", f"{result['wall_s']:.2f} s"),
    ]
    a = result.get("analytic")
    if a:
        rows += [row("analytic peak", f"{a['peak_n']:.4f} N"),
                 row("force RMS error", f"{a['rms_error_n']:.5f} N = {a['rms_error_pct']:.3f} % of peak"),
                 row("direction error", f"RMS {a['rms_angle_deg']:.3f}°, max {a['max_angle_deg']:.3f}° "
                                        f"({a['angle_ticks']} ticks with ≥ 10 % of peak)")]
    for label, p in (lat or {}).items():
        rows.append(row(f"{label} (µs)", f"p50 {p['p50']:.2f}, p99 {p['p99']:.2f}, p99.9 {p['p999']:.2f}, "
                                          f"max {p['max']:.2f} ({p['count']} ticks)"))
    for f in result.get("failures", []):
        rows.append(row("FAILED", f))
    imgs = "".join(f'<figure><img alt="{html.escape(alt)}" src="data:image/png;base64,{b64}"></figure>'
                   for alt, b64 in images)
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>palpa HIL: {html.escape(name)}</title>
<style>body{{font-family:sans-serif;max-width:1050px;margin:1em auto;color:#222}}
table{{border-collapse:collapse}}th,td{{border:1px solid #ccc;padding:3px 8px;text-align:left;font-size:14px}}
th{{background:#f4f4f4}}img{{max-width:100%}}.ok{{color:#070}}.bad{{color:#b00}}</style></head>
<body><p><a href="index.html">all cases</a></p><h1>{html.escape(name)}
<span class="{'ok' if result['verdict'] in ('ok', 'blessed') else 'bad'}">{html.escape(result['verdict'])}</span></h1>
<table>{''.join(rows)}</table>{imgs}</body></html>
"""


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--results", required=True, help="results/<mode> directory written by palpa hil run")
    ap.add_argument("-o", "--output", required=True, help="report directory")
    a = ap.parse_args()
    index_path = os.path.join(a.results, "index.json")
    if not os.path.exists(index_path):
        print(f"hil-report: {index_path} is missing (run palpa hil run first)", file=sys.stderr)
        return 2
    with open(index_path) as f:
        results = json.load(f)
    os.makedirs(a.output, exist_ok=True)
    summary = []
    links = []
    for r in results:
        name = r["case"]
        d = os.path.join(a.results, name)
        s = load_series(os.path.join(d, "series.csv"))
        images = []
        if s is not None and s.size > 1:
            images.append(("force magnitude vs time", force_plot(name, s, r)))
            images.append(("proxy vs HIP penetration", penetration_plot(name, s)))
        lat = None
        t = load_timing(os.path.join(d, "timing.csv"))
        if t is not None and t.size > 1:
            img, lat = latency_plot(name, t, r["mode"])
            images.append(("latency histogram", img))
        with open(os.path.join(a.output, f"{name}.html"), "w") as f:
            f.write(page(name, r, images, lat))
        # The same plots as files, for people who want one picture.
        for (alt, b64), suffix in zip(images, ("force", "penetration", "latency")):
            with open(os.path.join(a.output, f"{name}-{suffix}.png"), "wb") as f:
                f.write(base64.b64decode(b64))
        entry = {k: r[k] for k in ("case", "mode", "device", "verdict", "ticks", "contact_ticks", "max_force_n_seen",
                                   "max_slope_n", "min_proxy_phi_voxels", "exit_code", "failures")}
        if r.get("analytic"):
            entry["analytic"] = r["analytic"]
        entry["latency_us"] = lat or {}
        entry["summary"] = r.get("summary")
        summary.append(entry)
        cls = "ok" if r["verdict"] in ("ok", "blessed") else "bad"
        lat_txt = ""
        if lat:
            key = "wake-up latency" if "wake-up latency" in lat else "compute"
            p = lat[key]
            lat_txt = f"{key} p50 {p['p50']:.1f} / p99 {p['p99']:.1f} / p99.9 {p['p999']:.1f} / max {p['max']:.1f} µs"
        links.append(f'<tr><td><a href="{html.escape(name)}.html">{html.escape(name)}</a></td><td>{r["device"]}</td>'
                     f'<td>{r["ticks"]}</td><td>{r["max_force_n_seen"]:.3f}</td><td>{html.escape(lat_txt)}</td>'
                     f'<td class="{cls}">{html.escape(r["verdict"])}</td></tr>')
    with open(os.path.join(a.output, "summary.json"), "w") as f:
        json.dump(summary, f, indent=1, default=float)
    mode = results[0]["mode"] if results else "-"
    with open(os.path.join(a.output, "index.html"), "w") as f:
        f.write(f"""<!DOCTYPE html><html lang="en"><head><meta charset="utf-8"><title>palpa HIL report</title>
<style>body{{font-family:sans-serif;max-width:1050px;margin:1em auto}}table{{border-collapse:collapse}}
th,td{{border:1px solid #ccc;padding:3px 8px}}.ok{{color:#070}}.bad{{color:#b00}}</style></head><body>
<h1>palpa HIL report ({html.escape(mode)})</h1><table><tr><th>case</th><th>device</th><th>ticks</th>
<th>max |f| (N)</th><th>latency</th><th>verdict</th></tr>{''.join(links)}</table>
<p>summary.json holds the same figures for machines.</p></body></html>
""")
    print(f"hil-report: {len(results)} case page(s), index.html and summary.json in {a.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
