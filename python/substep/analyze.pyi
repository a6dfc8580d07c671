from typing import Dict, Optional, Sequence, Tuple, Union

import numpy as np

Grid = Union[Tuple[float, float, int], str]

def stability(
    *,
    case: str = "typical",
    eta_m: Optional[float] = None,
    eta_f: Optional[float] = None,
    zeta: Optional[float] = None,
    zeta_s: Optional[float] = None,
    error_force: str = "none",
    eta_p: float = 0.0,
    phase_lag: str = "none",
    k_sub: Sequence[int] = (1, 2, 3, 4, 5),
    omega: Grid = "0.015708:3.141593:200",
    vary: Union[Tuple[str, Grid], str] = "zeta_s=0:0.5:200",
) -> Dict[str, np.ndarray]: ...
def accuracy(
    *,
    case: str = "typical",
    eta_m: Optional[float] = None,
    eta_f: Optional[float] = None,
    zeta: Optional[float] = None,
    zeta_s: Optional[float] = None,
    error_force: str = "none",
    eta_p: Sequence[float] = (0.0,),
    k_sub: Sequence[int] = (1, 2, 5),
    eta_t: Sequence[float] = ...,
    vary: Optional[Union[Tuple[str, Grid], str]] = None,
) -> Dict[str, np.ndarray]: ...
def transfer_function(
    *,
    case: str = "typical",
    eta_m: Optional[float] = None,
    eta_f: Optional[float] = None,
    zeta: Optional[float] = None,
    zeta_s: Optional[float] = None,
    error_force: str = "none",
    eta_p: float = 0.0,
    k_sub: int = 1,
    eta_t: float = 0.05,
    r: Optional[Sequence[float]] = None,
) -> Dict[str, np.ndarray]: ...
def plan(
    config: object,
    *,
    dt: Optional[Sequence[float]] = None,
    k_sub: Optional[Sequence[int]] = None,
    delay: Optional[Sequence[float]] = None,
    tolerance: float = 0.02,
    margin: float = 1e-3,
    budget: float = 0.5,
) -> Dict[str, object]: ...
def verify() -> Dict[str, object]: ...
