"""Builds the ``meshless`` package with its protocol code generated at
build time: ``build_py`` runs ``grpc_tools.protoc`` (grpcio-tools, a
build requirement in pyproject.toml) on ``meshless/v1/*.proto`` and
writes the ``*_pb2.py``, ``*_pb2.pyi`` and ``*_pb2_grpc.py`` modules into
the build (or, for an editable install, next to the sources), so no
generated file is checked in.

The ``.proto`` files are found in ``proto/`` beside this file (a source
distribution carries a copy there: ``sdist`` adds it) or else in the
repository's ``proto/``, two folders up.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py
from setuptools.command.sdist import sdist

HERE = Path(__file__).resolve().parent
# In a source distribution, then in the repository.
PROTO_ROOTS = (HERE / "proto", HERE.parent.parent / "proto")
PACKAGE = Path("meshless") / "v1"


def proto_root() -> Path:
    """The folder that holds ``meshless/v1/*.proto``."""
    for root in PROTO_ROOTS:
        if (root / PACKAGE / "simulation.proto").is_file():
            return root
    raise RuntimeError(
        "meshless/v1/*.proto not found in "
        + " or ".join(str(root) for root in PROTO_ROOTS)
        + ": build from the repository's client/python or from a source distribution"
    )


def protos(root: Path) -> list[Path]:
    """Every ``.proto`` file of package ``meshless.v1``, sorted."""
    return sorted((root / PACKAGE).glob("*.proto"))


def generate(out: Path) -> None:
    """Runs protoc (grpcio-tools' own) on every ``.proto`` file, writing
    the modules of package ``meshless.v1`` under ``out``."""
    import grpc_tools
    from grpc_tools import protoc

    root = proto_root()
    well_known = Path(grpc_tools.__file__).resolve().parent / "_proto"
    args = [
        "grpc_tools.protoc",
        f"--proto_path={root}",
        f"--proto_path={well_known}",
        f"--python_out={out}",
        f"--pyi_out={out}",
        f"--grpc_python_out={out}",
        *(str(path) for path in protos(root)),
    ]
    if protoc.main(args) != 0:
        raise RuntimeError(f"protoc failed: {' '.join(args)}")


class BuildPy(build_py):
    """``build_py`` that also generates the protocol code."""

    def run(self) -> None:
        super().run()
        editable = getattr(self, "editable_mode", False)
        generate(HERE if editable else Path(self.build_lib))


class Sdist(sdist):
    """``sdist`` that carries the ``.proto`` files in ``proto/``, so that
    a wheel builds from the source distribution outside the repository."""

    def make_release_tree(self, base_dir: str, files: list[str]) -> None:
        super().make_release_tree(base_dir, files)
        root = proto_root()
        target = Path(base_dir) / "proto" / PACKAGE
        target.mkdir(parents=True, exist_ok=True)
        for path in protos(root):
            shutil.copy2(path, target / path.name)


setup(cmdclass={"build_py": BuildPy, "sdist": Sdist})
