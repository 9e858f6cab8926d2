"""The twin's physics: parameters (config/plant.yaml), the numba kernel (Eq. 1-12), the Plant."""
