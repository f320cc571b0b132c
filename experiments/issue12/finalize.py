"""Fill RESULTS.md's placeholders from table.md, summary.json and findings.md."""
import json
from pathlib import Path

HERE = Path(__file__).resolve().parent
s = json.loads((HERE / "summary.json").read_text())


def f(y):
    return f"{y:.2e}" if abs(y) < 0.01 and y else f"{y:.3f}"


def cell(v, key):
    x = s[v][key]
    return f"{f(x['median'])} [{f(x['min'])}, {f(x['max'])}]"


a1 = s["full+A1"]
n = len(a1["seeds"])
row = (f"n = {n}: success {cell('full+A1', 'default.success')}, RMS "
       f"{cell('full+A1', 'default.tracking_rms_success')}, excursion "
       f"{cell('full+A1', 'default.reel_excursion')}, effort "
       f"{cell('full+A1', 'default.reel_effort')}; generalisation suite success "
       f"{cell('full+A1', 'gen.success')}, RMS {cell('full+A1', 'gen.tracking_rms_success')}")
findings = (HERE / "findings.md").read_text().replace("A1ROW", row).replace(
    "MIXN", str(len(s["full-R1+mix"]["seeds"])))
text = (HERE / "RESULTS.md").read_text()
text = text.replace("TABLE_PLACEHOLDER", (HERE / "table.md").read_text().strip())
text = text.replace("FINDINGS_PLACEHOLDER", findings.strip())
(HERE / "RESULTS.md").write_text(text)
print(row)
