"""Pitfall P4 (shared/notes/dem_codes.md): YADE makes one contact per facet, so a sphere near an edge or vertex
shared by facets of one mesh is pushed twice (measured: e = 0.738 instead of 0.800 at 0.07 mm from the edge).
These functions resolve the facet contacts of one sphere with one mesh as the native solver does
(coupler/dem/meshes.py, after Santasusana et al. 2016): a face contact dominates the edges and vertices of that
face, an edge contact the vertices of that edge, and one edge or vertex reached from several facets counts once.

The source of this file is copied into every YADE script (adapters/yade/writer.py), where p4() takes the force and
torque of each dominated contact back from the sphere after the InteractionLoop. Plain Python only (no imports):
vectors are YADE Vector3 in the script and numpy arrays in the tests; both have .dot()."""


def feature(p, a, b, c):
    """Region of the closest point of triangle abc to p (Ericson 2005, 5.1.5, as coupler/dem/meshes.py):
    (0, 0) face, (1, k) edge k (0: ab, 1: bc, 2: ca), (2, k) vertex k (0: a, 1: b, 2: c)."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = ab.dot(ap), ac.dot(ap)
    if d1 <= 0 and d2 <= 0:
        return 2, 0
    bp = p - b
    d3, d4 = ab.dot(bp), ac.dot(bp)
    if d3 >= 0 and d4 <= d3:
        return 2, 1
    if d1 * d4 - d3 * d2 <= 0 and d1 >= 0 and d3 <= 0:
        return 1, 0
    cp = p - c
    d5, d6 = ab.dot(cp), ac.dot(cp)
    if d6 >= 0 and d5 <= d6:
        return 2, 2
    if d5 * d2 - d1 * d6 <= 0 and d2 >= 0 and d6 <= 0:
        return 1, 2
    if d3 * d6 - d5 * d4 <= 0 and d4 - d3 >= 0 and d5 - d6 >= 0:
        return 1, 1
    return 0, 0


def feature_key(face, tri, typ, loc):
    """Mesh-global key of a feature: the face index, the sorted vertex pair of an edge, or the vertex index."""
    if typ == 0:
        return face
    if typ == 1:
        return tuple(sorted((tri[loc], tri[(loc + 1) % 3])))
    return tri[loc]


def contains(tri_b, typ_b, key_b, typ_a, key_a):
    """Does feature b (a face with vertices tri_b, or an edge of it) contain the lower feature a?"""
    if typ_b == 0:
        return set(key_a) <= set(tri_b) if typ_a == 1 else key_a in tri_b
    return key_a in key_b


def resolve(feats):
    """feats: [(type, key, face vertices)] of one sphere's contacts with one mesh, in face order.
    Returns keep flags (the native hierarchy; False = dominated, its force must not act)."""
    keep = [True] * len(feats)
    for ia, (ta, ka, _) in enumerate(feats):
        if ta == 0:
            continue
        for ib, (tb, kb, trib) in enumerate(feats):
            if ib == ia or not keep[ib]:
                continue
            if (tb < ta and contains(trib, tb, kb, ta, ka)) or (tb == ta and kb == ka and ib < ia):
                keep[ia] = False
                break
    return keep
