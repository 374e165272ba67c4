"""Identification: circle point analysis, geometric and effect fits, identifiability."""
