"""Contact law composed of sub-models (like LAMMPS `pair_style granular`), one module per family:

  normal.py      hertz | hooke                         S_n, S_t, elastic normal force and energy
  damping.py     restitution | liggghts | yade         coefficient of restitution -> damping ratio beta
  tangential.py  history | no_history | incremental    Coulomb friction with a total spring (LIGGGHTS), without a
                                                       spring, or with an incremental one (YADE Mindlin)
  rolling.py     none | cdt | epsd2                    rolling-resistance torque
  (registry: coupler/contact_models.py, one row per model and the `[[contacts]]` parser)
  law.py         the law table (one row per material pair) and `contact_force`, the composed function the
                 pair, plane and mesh kernels inline

Default (normal hertz, damping restitution, tangential history, rolling none) is the Hertz-Mindlin law of
LIGGGHTS 3.8 `model hertz tangential history` (shared/notes/dem_codes.md).
"""
from coupler.dem.contact.damping import (beta_liggghts, beta_liggghts_hooke, beta_restitution, beta_yade,
                                         restitution_clamped)
from coupler.dem.contact.law import (NLAW, NLAW_HM, contact_force, damping_ratio, law_extra, law_row, law_table)
from coupler.dem.contact.normal import effective_shear, effective_young
from coupler.contact_models import FAMILIES, NORMAL, ROLLING, TANGENTIAL, parse_submodels

__all__ = ["beta_liggghts", "beta_liggghts_hooke", "beta_restitution", "beta_yade", "restitution_clamped",
           "NLAW", "NLAW_HM", "contact_force", "law_extra", "damping_ratio", "law_row", "law_table", "effective_shear",
           "effective_young", "FAMILIES", "NORMAL", "ROLLING", "TANGENTIAL", "parse_submodels"]
