"""Probability: Gaussians in information form (:mod:`.gaussian`), the GMM (:mod:`.gmm`) and
Gaussian mixture regression (:mod:`.gmr`). The bottom layer: numpy, SciPy and scikit-learn only."""
