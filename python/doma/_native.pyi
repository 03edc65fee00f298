"""Types of the compiled extension; the API with its docs is doma/__init__.py.

python/tests/test_native_stub.py checks every name and parameter here against the module."""

from typing import Any, Callable, Optional, Sequence

from numpy.typing import NDArray
import numpy as np

__version__: str

class Field:
    def warp_into(self, points: NDArray[np.float32], times: Sequence[float], out: NDArray[np.float32]) -> None: ...
    def jacobian_into(self, points: NDArray[np.float32], times: Sequence[float], out: NDArray[np.float32]) -> None: ...
    def complete(
        self, max_gap: Optional[str] = None, extrapolate: bool = False, method: Optional[str] = None
    ) -> tuple[bytearray, tuple[int, int], bytearray, Optional[list[int]]]: ...
    def evaluate(self, data: Optional[str] = None, masked: bool = False) -> str: ...
    def save(self, dir: str) -> None: ...
    @property
    def canonical(self) -> bytearray: ...
    @property
    def reference_frame(self) -> int: ...
    @property
    def run_dir(self) -> Optional[str]: ...
    @property
    def frames(self) -> int: ...
    @property
    def tracks(self) -> int: ...
    @property
    def config(self) -> str: ...
    @property
    def report(self) -> Optional[str]: ...
    @property
    def normalisation(self) -> tuple[tuple[float, float, float], float]: ...
    @property
    def backend(self) -> str: ...
    @property
    def model(self) -> str: ...

CHOICES: dict[str, list[str]]

def fit(
    tracks: NDArray[np.float32],
    observed: Optional[NDArray[np.uint8]] = None,
    *,
    out: Optional[str] = None,
    progress: bool = True,
    each: Optional[Callable[..., Any]] = None,
    overwrite: bool = False,
    **options: object,
) -> Field: ...
def resume(run_dir: str, progress: bool, each: Optional[Callable[..., Any]] = None) -> Field: ...
def load(run_dir: str, backend: Optional[str] = None) -> Field: ...
def read_tracks(
    path: str,
    layout: Optional[str] = None,
    frame: Optional[str] = None,
    count_hidden: bool = False,
    confidence: Optional[str] = None,
    visibility_threshold: Optional[float] = None,
    model_outputs: bool = False,
) -> tuple[
    bytearray,
    tuple[int, int],
    bytearray,
    Optional[bytearray],
    Optional[bytearray],
    Optional[bytearray],
    Optional[tuple[list[str], float, str]],
]: ...
def fill_into(
    tracks: NDArray[np.float32], observed: NDArray[np.uint8], filler: str, out: NDArray[np.float32]
) -> None: ...
def fill_file(
    path: str,
    out: str,
    fit: bool = False,
    max_gap: Optional[str] = None,
    extrapolate: bool = False,
    method: Optional[str] = None,
    overwrite: bool = False,
    flag_above_mm: float = 5.0,
) -> str: ...
def sequence_reads() -> int: ...
def main(argv: list[str]) -> int: ...
