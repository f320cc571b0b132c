import json, sys
rows = []
for g in ("0.1", "0.25", "0.5"):
    r = json.load(open(f"/work/runs/gain/eval_g{g}/results.json"))
    (name, b), = [(k, v) for k, v in r["policies"].items()]
    def cell(m, f):
        v = b[m]; ci = b["ci95"][m]
        return (f.format(v) if v is not None else "n/a") + ("" if ci is None else f" [{f.format(ci[0])}, {f.format(ci[1])}]")
    fails = sum(b["failures"].values())
    rows.append(f"| {g} | {b['n_runs']} | {cell('success', '{:.3f}')} | {cell('tracking_rms', '{:.2e}')} | {cell('reel_excursion', '{:.3f}')} | {cell('reel_effort', '{:.3f}')} | {fails}/{b['n_episodes']} |")
print("| increment gain | seeds | success | tracking RMS [rad] | reel excursion | reel effort | failed episodes |")
print("|---|---|---|---|---|---|---|")
print("\n".join(rows))
