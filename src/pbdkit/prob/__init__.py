"""Probability: Gaussians in information form (:mod:`.gaussian`), the GMM (:mod:`.gmm`),
Gaussian mixture regression (:mod:`.gmr`), rotations and poses (:mod:`.rotations`) and frames
(:mod:`.frames`). The bottom layer: numpy, SciPy and scikit-learn only."""
