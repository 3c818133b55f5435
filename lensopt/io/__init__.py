"""File input/output: atomic writes, CODE V sequence files."""
