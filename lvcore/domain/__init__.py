"""The fixed definitions every layer shares: what the numbers mean, named once.

* :mod:`lvcore.domain.units`: units and conversions (mm, mL, kPa, mmHg, degrees);
* :mod:`lvcore.domain.outputs`: the simulator's 25 outputs, their order and names;
* :mod:`lvcore.domain.conditions`: the simulator's default conditions apart from the chapter's emulator
  conditions, the chapter's reference θ̃, noise levels and the Holzapfel–Ogden population values;
* :mod:`lvcore.domain.physiology`: normal physiology (the Klotz et al. 2006 EDPVR and the typical EDV/V₀),
  pure functions.

Importing this package imports none of them.
"""
