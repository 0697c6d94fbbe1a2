"""Domain errors and reason codes for object sources, manifests and processing.

A failed object is a *status with a reason code* (:class:`Reason`), never a crashed batch:
the pipeline catches :class:`ObjectError` and records ``reason`` and ``message`` in the
object's cache entry. Manifest problems raise :class:`ManifestError` on load, because a bad
manifest is a user error that must be fixed before any work starts.
"""

from __future__ import annotations

import enum

from datagen.errors import DatagenError

__all__ = ["Reason", "ObjectError", "MeshProcessingError", "ManifestError", "SourceError", "check_manifest_file"]


class Reason(str, enum.Enum):
    """Stable reason codes recorded for failed objects and rejected manifests."""

    MISSING_FILE = "missing_file"            # the mesh file does not exist
    NOT_A_FILE = "not_a_regular_file"        # a directory, device, FIFO or looping symlink
    FILE_TOO_LARGE = "file_too_large"        # a file over its size cap (a mesh: ProcessConfig.max_mesh_bytes)
    UNREADABLE_MESH = "unreadable_mesh"      # the file is not a mesh the loader understands
    EMPTY_MESH = "empty_mesh"                # no vertices or no faces
    NON_FINITE = "non_finite_vertices"       # NaN or inf coordinates
    HUGE_COORDINATES = "huge_coordinates"    # |coordinate| above ProcessConfig.max_abs_coordinate
    TOO_LARGE = "too_many_faces"             # face count above ProcessConfig.max_faces
    DEGENERATE = "degenerate_mesh"           # zero extent, zero area or zero volume
    COACD_FAILED = "coacd_failed"            # CoACD raised
    COACD_NO_PARTS = "coacd_no_parts"        # CoACD returned no part above the volume floor
    SURFACE_FAILED = "surface_failed"        # no watertight simplified surface could be built
    MJCF_FAILED = "mjcf_failed"              # MuJoCo rejected the model of the pieces
    SHA_MISMATCH = "sha256_mismatch"         # the file changed since the manifest was built
    TIMEOUT = "timeout"                      # processing exceeded its time limit (isolate.py)
    CRASHED = "crashed"                      # the processing process died (isolate.py)
    NATIVE_SIZE = "native_size_out_of_range"  # scale "native" on a mesh whose units are not metres
    # manifest-level reasons
    MALFORMED_LINE = "malformed_line"        # not a JSON object
    SCHEMA = "schema"                        # missing/extra/mistyped field
    DUPLICATE_ID = "duplicate_id"            # two lines with the same id
    PATH_ESCAPES_ROOT = "path_escapes_root"  # a source path resolves outside its root
    UNKNOWN_SOURCE = "unknown_source"        # the source URI names no known source


class ObjectError(DatagenError):
    """Base error: carries a :class:`Reason` code and the thing it concerns.

    The message names the thing (object id, file or manifest line) and the reason, and where
    possible the remedy.
    """

    def __init__(self, reason: Reason, thing: str, detail: str):
        self.reason = Reason(reason)
        self.thing = thing
        self.detail = detail
        super().__init__(f"{thing}: {self.reason.value}: {detail}")

    def __reduce__(self):  # picklable (Ray ships exceptions between processes)
        return self.__class__, (self.reason, self.thing, self.detail)


class MeshProcessingError(ObjectError):
    """A mesh could not be loaded, validated, decomposed or modelled."""


class ManifestError(ObjectError):
    """A manifest file or line is invalid."""

    @classmethod
    def of_input(cls, exc) -> "ManifestError":
        """The error of a manifest file that cannot be read (a `datagen._bounded.InputError`)."""
        reason = {"missing_file": Reason.MISSING_FILE, "file_too_large": Reason.FILE_TOO_LARGE,
                  "not_text": Reason.MALFORMED_LINE}.get(exc.reason, Reason.NOT_A_FILE)
        return cls(reason, exc.path, exc.detail)


def check_manifest_file(path) -> None:
    """`ManifestError` unless ``path`` is a regular file within the manifest cap (nothing read;
    for commands, before their heavy imports)."""
    from datagen import _bounded

    try:
        _bounded.check_regular(path, _bounded.MANIFEST_BYTES, "manifest")
    except _bounded.InputError as exc:
        raise ManifestError.of_input(exc) from None


class SourceError(ObjectError):
    """A source URI is unknown or cannot enumerate its objects."""
