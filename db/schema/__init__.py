"""JSON Schemas of the railval file formats (package data)."""
