"""Generates the build-time parts of the recog_client package (setup.py runs it), that is

- ``recog_client/_proto/``: the protobuf and gRPC stubs of ``proto/recognition/v1/*.proto`` and
  ``proto/grpc/health/v1/health.proto`` with their ``.pyi`` type stubs (protoc ``--python_out``,
  ``--pyi_out`` and ``grpc_python_plugin``). protoc writes absolute imports
  (``from recognition.v1 import common_pb2``), which would need the generic top-level package
  ``recognition`` on ``sys.path``; they are rewritten to relative ones (``from . import
  common_pb2``), so the stubs live inside this package and collide with nothing.
- ``recog_client/service_config.json``: the clients' retry policy, copied from
  ``proto/service_config.json`` (the one published place).
- ``recog_client/_version.py``: the project's version, read from ``project(recog VERSION ...)``
  in the top ``CMakeLists.txt``, which is also the package's version.

The repository's ``proto/`` and ``CMakeLists.txt`` are found two levels up from this file;
``RECOG_SOURCE_DIR`` names another checkout. protoc and the plugin are taken from ``PROTOC`` and
``GRPC_PYTHON_PLUGIN``, else from ``PATH`` (Debian: protobuf-compiler, protobuf-compiler-grpc).
Run as a script, ``stubgen.py LIB`` builds the whole package into ``LIB/recog_client`` (the
hand-written modules copied, the rest generated): CMake does so for the tests, without the
setuptools machinery that would write ``*.egg-info`` into the source tree.
Only the standard library is used.
"""

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
SOURCE_DIR = Path(os.environ.get("RECOG_SOURCE_DIR", HERE.parent.parent))
PACKAGE = HERE / "recog_client"
PROTO_DIR = SOURCE_DIR / "proto"
PROTOS = [f"recognition/v1/{name}.proto" for name in
          ("common", "place", "object", "repository", "admin")] + ["grpc/health/v1/health.proto"]


def project_version() -> str:
    """The version in ``project(recog VERSION x.y.z ...)`` of the top CMakeLists.txt."""
    text = (SOURCE_DIR / "CMakeLists.txt").read_text(encoding="utf-8")
    match = re.search(r"project\(\s*recog\s+VERSION\s+([0-9][0-9.]*)", text)
    if match is None:
        raise RuntimeError(f"no `project(recog VERSION ...)` in {SOURCE_DIR / 'CMakeLists.txt'}")
    return match.group(1)


def tool(variable: str, name: str) -> str:
    """The path of a build tool: the environment variable ``variable`` or ``name`` on PATH."""
    path = os.environ.get(variable) or shutil.which(name)
    if not path:
        raise RuntimeError(f"{name} not found (set {variable}; Debian: protobuf-compiler and "
                           "protobuf-compiler-grpc)")
    return path


def make_imports_relative(stub: Path, proto_package: str) -> None:
    """Rewrites ``from <proto_package> import x`` (a sibling stub) to ``from . import x``."""
    text = stub.read_text(encoding="utf-8")
    text = re.sub(rf"^from {re.escape(proto_package)} import ", "from . import ", text,
                  flags=re.MULTILINE)
    if re.search(r"^(from|import) (recognition|grpc\.health)\b", text, flags=re.MULTILINE):
        raise RuntimeError(f"{stub} imports a proto package that is not its own")
    stub.write_text(text, encoding="utf-8")


def generate_stubs(package_dir: Path) -> None:
    """Writes the stubs, the retry policy and the version into ``package_dir`` (recog_client/)."""
    out = package_dir / "_proto"
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    subprocess.run([tool("PROTOC", "protoc"), f"-I{PROTO_DIR}", f"--python_out={out}",
                    f"--pyi_out={out}", f"--grpc_out={out}",
                    f"--plugin=protoc-gen-grpc={tool('GRPC_PYTHON_PLUGIN', 'grpc_python_plugin')}",
                    *[str(PROTO_DIR / proto) for proto in PROTOS]], check=True)
    for proto in PROTOS:
        directory = out / Path(proto).parent
        for stub in directory.glob("*_pb2*.py*"):
            make_imports_relative(stub, str(Path(proto).parent).replace("/", "."))
        while directory != package_dir:  # every level is a regular package
            (directory / "__init__.py").touch()
            directory = directory.parent
    shutil.copyfile(PROTO_DIR / "service_config.json", package_dir / "service_config.json")
    (package_dir / "_version.py").write_text(
        f'"""The version of recog_client (generated from CMakeLists.txt)."""\n\n'
        f'__version__ = "{project_version()}"\n', encoding="utf-8")


def main() -> int:
    """``stubgen.py LIB``: the whole package into ``LIB/recog_client``."""
    if len(sys.argv) != 2:
        print("usage: stubgen.py LIB", file=sys.stderr)
        return 2
    package_dir = Path(sys.argv[1]) / "recog_client"
    if package_dir.exists():
        shutil.rmtree(package_dir)
    shutil.copytree(PACKAGE, package_dir, ignore=shutil.ignore_patterns("__pycache__"))
    generate_stubs(package_dir)
    return 0


if __name__ == "__main__":
    sys.exit(main())
