"""Registration of strike logs into the target body frame, surface reconstruction, comparisons."""
