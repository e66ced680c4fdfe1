"""docs/artifact-schema.json under real Ajv (the JSON Schema validator of Node) in strict mode:
``new Ajv2020({strict: true})`` compiles it (strict mode refuses a keyword without its ``type``,
union types, open tuples, a ``required`` name not declared beside it), every shipped artifact
validates, and a grid move named "NE" does not.

It runs where ``node`` is on PATH and can load a local Ajv 8 (``npm install ajv@8`` in a folder,
then ``NODE_PATH=FOLDER/node_modules``, or a ``node_modules`` above the repository); elsewhere it
is skipped, saying which is missing. tests/synthesis/test_artifact_schema.py holds the same file
to Python's ``jsonschema``.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest

from flowtest_env.artifacts import ARTIFACT_DIR

ROOT = Path(__file__).resolve().parents[2]
SCHEMA_FILE = ROOT / "docs" / "artifact-schema.json"
SHIPPED = sorted(ARTIFACT_DIR.glob("*.json"))

CHECK = """
const Ajv2020 = require("ajv/dist/2020");
const fs = require("fs");
const [schemaPath, ...files] = process.argv.slice(1);
const validate = new Ajv2020({strict: true}).compile(JSON.parse(fs.readFileSync(schemaPath, "utf8")));
const out = {};
for (const f of files) {
  const ok = validate(JSON.parse(fs.readFileSync(f, "utf8")));
  out[f] = ok ? null : validate.errors.map((e) => `${e.instancePath} ${e.message}`);
}
process.stdout.write(JSON.stringify(out));
"""


def _ajv() -> str:
    """The path of a loadable Ajv 8 (its draft 2020-12 build); skips the test without node or Ajv."""
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is not on PATH (the Ajv check needs Node.js)")
    found = subprocess.run([node, "-e", "process.stdout.write(require.resolve('ajv/dist/2020'))"], cwd=ROOT, capture_output=True, text=True, timeout=60)
    if found.returncode != 0:
        pytest.skip("no local Ajv: `npm install ajv@8` in a folder and set NODE_PATH=FOLDER/node_modules")
    return found.stdout


def test_ajv_strict_mode_compiles_the_schema_and_validates_every_shipped_artifact(tmp_path: Path) -> None:
    assert _ajv()
    grid = json.loads((ARTIFACT_DIR / "maze2.json").read_text())
    grid["system"]["action"][0] = "NE"
    ne = tmp_path / "maze2-NE.json"
    ne.write_text(json.dumps(grid))
    files = [str(p) for p in SHIPPED] + [str(ne)]
    run = subprocess.run(["node", "-e", CHECK, str(SCHEMA_FILE), *files], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, f"Ajv (strict) refuses the schema: {run.stderr[-3000:]}"
    verdicts = json.loads(run.stdout)
    assert len(SHIPPED) >= 9
    assert {Path(f).name: v for f, v in verdicts.items() if v is not None and f != str(ne)} == {}
    assert verdicts[str(ne)] and any(e.startswith("/system/action/0 ") for e in verdicts[str(ne)]), verdicts[str(ne)]
