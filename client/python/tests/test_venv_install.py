"""The installation of recog_client as a user does it, and the example it documents.

Copies what the package is built from (the top CMakeLists.txt, proto/, client/python/) to a
temporary checkout, runs there the install command of client/python/README.md verbatim (a fresh
virtual environment that sees Debian's python3-grpcio, pip offline), checks what was installed
(version, .pyi types, py.typed), then runs examples/stream_corridor.py with the environment's
interpreter against a recogd on tests/data/corridor, and checks that it prints exactly the loops
`recog eval place` finds on the same frames with the same detector settings, then its summary.

Environment (ctest sets it): RECOGD, RECOG, RECOG_SOURCE_DIR, RECOG_VERSION, and PYTHONPATH with
the built package (for this harness only: the example runs without it). Exits with 77 (skipped)
only when the interpreter has no ensurepip (Debian: python3-venv), so no environment can exist.
"""

import importlib.util
import json
import os
import shutil
import subprocess
import sys
import tempfile
import unittest
from pathlib import Path

if importlib.util.find_spec("ensurepip") is None:  # what `python3 -m venv` needs for pip
    print("SKIP: no ensurepip (Debian: apt-get install python3-venv)", file=sys.stderr)
    sys.exit(77)

from recogd_process import Recogd

SOURCE = Path(os.environ.get("RECOG_SOURCE_DIR", Path(__file__).resolve().parents[3]))
README = SOURCE / "client" / "python" / "README.md"
#: The documented command, run from the repository's root.
INSTALL = ("/usr/bin/python3 -m venv --system-site-packages .venv && "
           ".venv/bin/pip install --no-build-isolation --no-index ./client/python")
#: The example's detector settings, for recog eval place.
PARAMS = "temporal_matches: 0\nrecent_frames: 1\n"


class VenvInstallTest(unittest.TestCase):
    """One installation for the class (it takes most of the test's time)."""

    @classmethod
    def setUpClass(cls):
        """Copies the sources and runs the documented install command."""
        cls.tmp = tempfile.TemporaryDirectory(prefix="recog-python-venv-")
        cls.checkout = Path(cls.tmp.name) / "recog"
        ignore = shutil.ignore_patterns("build", "*.egg-info", "__pycache__", ".venv")
        shutil.copytree(SOURCE / "proto", cls.checkout / "proto")
        shutil.copytree(SOURCE / "client" / "python", cls.checkout / "client" / "python",
                        ignore=ignore)
        shutil.copy(SOURCE / "CMakeLists.txt", cls.checkout)
        # The user's environment: no build-tree package, no pip cache of earlier runs.
        cls.environment = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
        cls.environment["PIP_NO_CACHE_DIR"] = "1"
        command = INSTALL.replace("/usr/bin/python3", sys.executable, 1)
        cls.install = subprocess.run(["bash", "-c", command], cwd=cls.checkout,
                                     env=cls.environment, capture_output=True, text=True,
                                     timeout=240, check=False)
        cls.python = cls.checkout / ".venv" / "bin" / "python"

    @classmethod
    def tearDownClass(cls):
        """Removes the checkout and its environment."""
        cls.tmp.cleanup()

    def run_in_venv(self, *args: str, env: dict | None = None) -> str:
        """Runs the environment's python with ``args`` outside the checkout; its stdout."""
        run = subprocess.run([str(self.python), *args], cwd=self.tmp.name,
                             env=env or self.environment, capture_output=True, text=True,
                             timeout=120, check=False)
        self.assertEqual(run.returncode, 0, run.stderr)
        return run.stdout

    def test_the_readme_documents_the_command_this_test_runs(self):
        self.assertTrue(INSTALL in README.read_text(encoding="utf-8"), f"{README}: {INSTALL}")

    def test_the_package_is_installed_with_its_version_and_types(self):
        self.assertEqual(self.install.returncode, 0, self.install.stdout + self.install.stderr)
        out = self.run_in_venv("-c", (
            "import importlib.metadata, pathlib, sys, recog_client as r\n"
            "root = pathlib.Path(r.__file__).parent\n"
            "print(root.is_relative_to(sys.prefix), "
            "importlib.metadata.version('recog-client'), r.__version__, "
            "(root / 'py.typed').exists(), "
            "len(list((root / '_proto').rglob('*_pb2.pyi'))), "
            "(root / 'service_config.json').exists())"))
        self.assertEqual(out.split(), ["True", os.environ.get("RECOG_VERSION", "0.1.0"),
                                       os.environ.get("RECOG_VERSION", "0.1.0"), "True", "6",
                                       "True"])

    def test_the_example_gets_the_loops_of_recog_eval_place(self):
        self.assertEqual(self.install.returncode, 0, self.install.stdout + self.install.stderr)
        corridor = SOURCE / "tests" / "data" / "corridor"
        params = Path(self.tmp.name) / "params.yaml"
        params.write_text(PARAMS, encoding="utf-8")
        evaluation = subprocess.run([os.environ["RECOG"], "eval", "place", "--images",
                                     str(corridor), "--params", str(params), "--json", "-q"],
                                    capture_output=True, text=True, timeout=120, check=True)
        evaluated = [f"{Path(loop['query_file']).name} revisits {Path(loop['match_file']).name}"
                     for loop in json.loads(evaluation.stdout)["loops"]
                     if loop["status"] == "loop_detected"]
        self.assertTrue(evaluated)  # the settings make the fixture's revisits loops

        server = Recogd()
        try:
            server.wait_until_serving()
            example = self.checkout / "client" / "python" / "examples" / "stream_corridor.py"
            streamed = self.run_in_venv(str(example), str(corridor), "temporal_matches=0",
                                        "recent_frames=1",
                                        env={**self.environment, "RECOG_SERVER": server.target})
        finally:
            server.stop()
        loops = f"{len(evaluated)} loop" + ("" if len(evaluated) == 1 else "s")
        self.assertEqual(streamed.splitlines(), evaluated + [f"4 frames, {loops}"])


if __name__ == "__main__":
    unittest.main(verbosity=2)
