"""Adapters from chronogym's vector envs to other RL libraries.

Each adapter is its own module and imports its library only when imported itself:
``import chronogym.integrations.sb3`` needs Stable-Baselines3 (``pip install
"chronogym[sb3]"``); ``import chronogym`` never loads it.
"""
