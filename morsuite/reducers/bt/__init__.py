"""Balanced truncation of the index-3 second-order system on LR-ADI Gramian factors: ``bt`` with
its second-order levels and ``bt-fl``, frequency-limited to a band."""
