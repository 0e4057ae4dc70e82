"""Importers: recordings made by other tools, turned into station capture bundles."""
