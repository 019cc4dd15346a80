"""Figures and tables from run and sweep folders (the only package that draws)."""
