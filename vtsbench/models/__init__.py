"""Reference networks: the dual-head TimeSformer for slip and the ResNet-50 for static recognition.

Import the submodules directly (``vtsbench.models.timesformer``, ``vtsbench.models.resnet``);
this package imports nothing heavy so that ``import vtsbench`` stays fast. What prepares their
input (crops, motion channels, symmetries, augmentation) is in ``vtsbench.transforms``.
"""
