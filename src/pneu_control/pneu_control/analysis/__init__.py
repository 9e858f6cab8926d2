"""Analysis of recorded runs: the paper's metrics (Eq. 37), fault marks, figures."""
