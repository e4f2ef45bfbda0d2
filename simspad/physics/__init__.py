"""Physics and numerics shared by every stage: radiometry, SPAD detection statistics, keyed random streams.

Pure functions of arrays and numbers; nothing here reads or writes files or knows about the pipeline.
"""
