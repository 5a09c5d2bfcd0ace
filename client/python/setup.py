"""Builds the recog_client package (pyproject.toml): the modules of recog_client/ plus what
stubgen.py generates at build time (the gRPC stubs with their .pyi types, the retry policy, the
version read from the top CMakeLists.txt, which is also the package's version).
"""

import sys
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

sys.path.insert(0, str(Path(__file__).resolve().parent))
import stubgen  # noqa: E402  (next to this file)


class BuildWithStubs(build_py):
    """build_py that also generates the stubs into the built package."""

    def run(self) -> None:
        """Copies the modules, then generates the rest next to them."""
        super().run()
        stubgen.generate_stubs(Path(self.build_lib) / "recog_client")


setup(version=stubgen.project_version(), packages=["recog_client"],
      package_data={"recog_client": ["py.typed"]}, cmdclass={"build_py": BuildWithStubs})
