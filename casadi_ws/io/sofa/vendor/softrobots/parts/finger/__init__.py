# -*- coding: utf-8 -*-
"""
Template for a robot finger.

Content:
********
.. autosummary::

   Finger

.. autofunction:: Finger

"""
from softrobots.parts.finger.finger import Finger
