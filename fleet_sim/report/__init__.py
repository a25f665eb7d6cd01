"""Figures and the HTML/PDF report."""
