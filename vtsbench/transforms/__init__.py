"""Input preparation for the models: crops around the contact (`contact_crop`), the motion
channels (`motion`), the symmetries of the frames with the direction labels mapped
(`symmetry`), augmentation of static images (`augment`), the modalities' channels
(`modality`), and the datasets of crops made once and cached (`cache`, `crops`).

Import the submodules directly; this package imports nothing heavy.
"""
