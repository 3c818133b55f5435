"""Quality assurance over whole lenses: regression checks against a baseline (``check``) and what
accuracy costs in time (``accuracy``). Sits beside ``optim``/``imaging`` and uses them."""
