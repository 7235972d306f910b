"""
Choosing a model: held-out scores and a choice with how sure it is
==================================================================

Prandtl-Ishlinskii, Preisach, Duhem and Bouc-Wen models describe the same loop with different
assumptions (congruent minor loops or not, a grid or five physical parameters). Which one
holds for *your* actuator is a question for data the model was not fitted on.
:func:`piezohyst.compare_models` fits each on the first part of a record and scores it on
the rest; :func:`piezohyst.select_model` makes the choice inside one record by forward
chaining and says which candidates the record cannot tell apart.

The actuator here is not the bench the defaults were designed on: a capacitor whose
hysteresis follows a Bouc-Wen law (``ph.simulate(plant="bouc-wen")``).
"""

import matplotlib.pyplot as plt

import piezohyst as ph

rec = ph.simulate(plant="bouc-wen", signal="decaying", duration=30.0, seed=1)

# %%
# Held-out scores of four families
# --------------------------------
cmp = ph.compare_models(
    {"classical PI": ph.ClassicalPI(10), "active PI": ph.ActivePI(10),
     "Preisach": ph.PreisachModel(), "Bouc-Wen": ph.BoucWenModel()},
    rec.voltage, rec.charge, t=rec.t, train=0.7,
)  # fmt: skip
print(cmp.table())

fig, ax = plt.subplots(figsize=(6, 3.2))
rows = sorted(cmp.rows, key=lambda r: r.test_nrmse)
ax.barh([r.name for r in rows], [100 * r.test_nrmse for r in rows])
ax.set(xlabel="held-out NRMSE (%)", title="the last 30 % of the record, never fitted on")
fig.tight_layout()

# %%
# The choice inside the record
# ----------------------------
# ``select_model`` fits every candidate's defaults on the first half and the first three
# quarters, scores each on what follows, and takes the simplest near the best; its table
# gives each candidate's margin with a standard error.
choice = ph.select_model(rec.voltage, rec.charge, t=rec.t)
print(choice.table())
print("chosen:", type(choice.model).__name__)
