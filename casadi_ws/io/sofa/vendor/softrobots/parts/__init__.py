# -*- coding: utf-8 -*-
"""
Templates for robot parts.

Content of the library
**********************

.. autosummary::
    :toctree: _autosummary

    parts.finger


"""

__all__=["finger","Bunny"]
