"""SimSPAD: physically rendered synthetic SPAD, frame and event datasets.

See ``DESIGN.md`` (the contract) and ``docs/internals.md`` (the package's layers and where to add things).
"""

__version__ = "0.1.0"
