"""Drawing a cut: the cut renderer, the seams between levels, front-to-back order."""
