"""Spline-wavelet pyramids (Steinberger 2010): filters, transform, store, chunk selection and
reconstruction."""
