"""Small helpers every stage uses: array kernels, progress, quiet native
libraries, one-line text, the time limit, freed memory."""
