"""SimSPAD: physically rendered synthetic SPAD, frame and event datasets.

See ``DESIGN.md`` (the contract) and ``docs/internals.md`` (module interfaces).
"""

__version__ = "0.1.0"
