"""From measurements to experimental models: excitation signals, FRF estimation, black-box models (ARX, ARMAX,
OE, BJ) with order selection and pruning, frequency-domain rational fits, modal extraction (LSCF / LSFD with
stabilization diagrams) and rigid-body motion reconstruction."""

__all__: list[str] = []
