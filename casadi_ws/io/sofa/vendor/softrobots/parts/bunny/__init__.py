# -*- coding: utf-8 -*-
"""
Template for deformable (Stanford) bunny, actuated with pressure.

Content:
********
.. autosummary::

   A (Stanford) bunny with a cavity, which can either by actuated by pressure or volume change. This part is used in some tutorials.

.. autofunction:: createBunny

"""
from softrobots.parts.bunny.Bunny import Bunny
