"""The IRKA family on one engine: the paper's projector-free second-order IRKA (``irka``),
the explicit Pi-projected baseline (``irka-projected``) and the first-order tangential IRKA
(``irka-fo``), with their shift machinery, surrogates and safeguards."""
