"""What runs leave for people and scripts: VTU/PVD series, summary.json, plots, the progress line."""
