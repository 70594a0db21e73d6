"""Multiresolution rendering: brick pyramids, brick trees and the cut drawn each frame.

Nothing is imported here, so ``import splinecast`` stays fast; import the submodules you need.
"""
