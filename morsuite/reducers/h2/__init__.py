"""The structure-preserving H2 descent (``so-h2``) and its numerics: the H2 gradient, the
pole/residue and cluster descents, the stationarity certificate and L-BFGS."""
