import os
from typing import Any, Dict, Optional, Union

def rths(
    *,
    case: Optional[int] = None,
    intensity: float = 0.4,
    controller: Optional[str] = None,
    config: Optional[Union[str, os.PathLike[str]]] = None,
    algorithm: str = "benchmark",
) -> Dict[str, Any]: ...
