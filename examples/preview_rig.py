"""See a rig before rendering it: the four cameras, the laser sheet, the seeding box and the
reconstruction volume of scenes/tomo4/experiment.toml in 3D, what each camera's sensor sees
of them, and the same experiment with one camera aimed 30 mm off, which the preview warns
about (as ``mitpiv run --check`` does) and draws.

    .venv/bin/python examples/preview_rig.py            # a few seconds: nothing is rendered
    .venv/bin/python examples/preview_rig.py --small    # the same (the flag of the test suite's run)

The same from the command line:
``.venv/bin/mitpiv preview scenes/tomo4/experiment.toml --out out/preview``. Writes into
out/examples/preview_rig/: tomo4/rig.png (the rig; also docs/examples/preview_rig.png),
tomo4/views.png, tomo4/rig.vtu (open it in ParaView, colour by ``part``), tomo4/rig.json,
and the same four files of the misaimed rig in misaimed/.
"""

import argparse
import warnings
from pathlib import Path

from mitpiv.errors import MitpivWarning
from mitpiv.studies.preview import preview

cli = argparse.ArgumentParser(description="preview the tomo4 rig before any render")
cli.add_argument("--small", action="store_true", help="accepted for the test suite; a preview is small already")
cli.add_argument("--out", default="out/examples/preview_rig", help="output folder")
args = cli.parse_args()
out = Path(args.out)
root = Path(__file__).resolve().parents[1]
experiment = root / "scenes" / "tomo4" / "experiment.toml"

res = preview(experiment, out / "tomo4")
for cam, c in res["coverage"]["cameras"].items():
    print(f"{cam}: sees {100 * c['fraction']:.0f} % of the reconstruction volume")
print(f"-> {out / 'tomo4' / 'rig.png'}, {out / 'tomo4' / 'views.png'}, {out / 'tomo4' / 'rig.vtu'}")

# The same rig with cam0 aimed 30 mm down the laser axis: an edited copy of the scene (its
# particle files are not needed for a preview) and of the experiment pointing at it.
scene = (root / "scenes" / "tomo4" / "scene.xml").read_text()
aim = '<float name="azimuth_deg" value="25"/>'
(out / "misaimed").mkdir(parents=True, exist_ok=True)
(out / "misaimed" / "scene.xml").write_text(scene.replace(aim, aim + '<point name="target" value="30, 0, 0"/>', 1))
(out / "misaimed" / "experiment.toml").write_text(experiment.read_text())
with warnings.catch_warnings(record=True) as caught:  # printed below, one line each
    warnings.simplefilter("always", MitpivWarning)
    bad = preview(out / "misaimed" / "experiment.toml", out / "misaimed")
for text in bad["warnings"]:
    print(f"warning: {text[:200]}...")
print(f"-> {out / 'misaimed' / 'views.png'}")
