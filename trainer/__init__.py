"""GratNet's offline stage: height fields, the Fourier-optics ground truth, training (torch only there)."""
