"""The scene kinds of multiresolution data: multiscale (cut of a pyramid), wavelet, and the
composite label and channel scenes."""
