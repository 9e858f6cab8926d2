"""Observers the algorithms share: the ESO (Eq. 13-18), the n-state chain ESO, the TD (Eq. 23-24)."""
