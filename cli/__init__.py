"""The ``recon`` command: a thin shell over formats, sim, metrics and recon."""
