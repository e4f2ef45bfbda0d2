"""Hostile-input suite: data loss, special files, symbolic links, crafted recordings, unbounded runs, disk full,
kill -9 and concurrent runs. Each test states the promise of docs/trust.md it checks."""
