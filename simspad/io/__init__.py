"""File formats of DESIGN §5 and nothing else. Imports nothing from the rest of simspad but ``errors``."""
