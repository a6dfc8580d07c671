import os
from typing import Any, Dict, Optional, Sequence, Union

def rths(
    *,
    case: Optional[int] = None,
    intensity: float = 0.4,
    controller: Optional[str] = None,
    config: Optional[Union[str, os.PathLike[str]]] = None,
    algorithm: str = "benchmark",
    record: Optional[Union[str, os.PathLike[str]]] = None,
    perturbed: Optional[int] = None,
    seed: int = 1,
    k_sub: Optional[Sequence[int]] = None,
) -> Dict[str, Any]: ...

def compare(
    *,
    case: Optional[int] = None,
    intensity: float = 0.4,
    record: Optional[Union[str, os.PathLike[str]]] = None,
    perturbed: int = 20,
    seed: int = 1,
) -> Dict[str, Any]: ...
