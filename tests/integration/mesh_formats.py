#!/usr/bin/env python3
"""Writes a unit cube (8 vertices, 12 triangles, [0,1]^3) in the formats the
readers take, plus malformed and lying-count variants of each, into DIR.

    mesh_formats.py DIR

Files: cube_bin.stl (header starting with "solid "), cube_ascii.stl,
cube_bin.ply (little endian), cube_be.ply, cube_ascii.ply (quads: 6 faces),
cube.gltf (embedded data: URI buffer), cube.glb (a node translating by
(10, 20, 30) and scaling by 2), cube.off (quads), variants exporters write
(cube_upper.stl, cube_bom.stl, cube_latin1.obj, cube_cr.obj, cube_rgba.obj,
cube_long.off, cube_4.off, cube_n.off, cube_deep.gltf, cube_trailing.stl,
cube_trailing_solid.stl, cube_ind.stl, cube_glued.off, cube_maplib.obj),
cube_morph.gltf and cube_morph_node.gltf (a morph target at the mesh's and
the node's weights), cube_skin.gltf (skinned to one joint), instances.glb (200000 nodes), primitives.glb (40000
primitives over one accessor of 400000 vertices), and malformed ones.
Standard library only."""
import base64
import json
import os
import struct
import sys

V = [(x, y, z) for z in (0, 1) for y in (0, 1) for x in (0, 1)]
# Quads, outward: -z, +z, -y, +y, -x, +x
Q = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
T = [t for a, b, c, d in Q for t in ((a, b, c), (a, c, d))]


def stl_binary(header=b"solid cube (binary)"):
    out = header.ljust(80, b" ") + struct.pack("<I", len(T))
    for t in T:
        out += struct.pack("<3f", 0, 0, 0)
        for i in t:
            out += struct.pack("<3f", *V[i])
        out += b"\0\0"
    return out


def stl_ascii():
    s = "solid cube\n"
    for t in T:
        s += " facet normal 0 0 0\n  outer loop\n"
        for i in t:
            s += "   vertex %g %g %g\n" % V[i]
        s += "  endloop\n endfacet\n"
    return (s + "endsolid cube\n").encode()


def ply(fmt, faces, nverts=None, nfaces=None):
    head = "ply\nformat %s 1.0\ncomment cube\nelement vertex %d\n" % (fmt, nverts or len(V))
    head += "property float x\nproperty float y\nproperty float z\n"
    head += "element face %d\nproperty list uchar int vertex_indices\nend_header\n" % (
        nfaces or len(faces))
    if fmt == "ascii":
        body = "".join("%g %g %g\n" % v for v in V)
        body += "".join("%d %s\n" % (len(f), " ".join(map(str, f))) for f in faces)
        return (head + body).encode()
    e = "<" if fmt == "binary_little_endian" else ">"
    body = b"".join(struct.pack(e + "3f", *v) for v in V)
    for f in faces:
        body += struct.pack(e + "B%di" % len(f), len(f), *f)
    return head.encode() + body


def off(nv=None, nf=None):
    s = "OFF\n# a cube\n%d %d 0\n" % (nv or len(V), nf or len(Q))
    s += "".join("%g %g %g\n" % v for v in V)
    s += "".join("4 %d %d %d %d\n" % f for f in Q)
    return s.encode()


def gltf_parts(count=None, node=None):
    pos = b"".join(struct.pack("<3f", *v) for v in V)
    idx = b"".join(struct.pack("<H", i) for t in T for i in t)
    binary = idx + pos  # idx is 72 bytes: pos stays 4-aligned
    doc = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [node or {"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 1}, "indices": 0}]}],
        "buffers": [{"byteLength": len(binary)}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": len(idx), "target": 34963},
            {"buffer": 0, "byteOffset": len(idx), "byteLength": len(pos), "target": 34962},
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5123, "count": count or len(idx) // 2,
             "type": "SCALAR"},
            {"bufferView": 1, "componentType": 5126, "count": len(V), "type": "VEC3",
             "min": [0, 0, 0], "max": [1, 1, 1]},
        ],
    }
    return doc, binary


def gltf(count=None, uri=None):
    doc, binary = gltf_parts(count)
    doc["buffers"][0]["uri"] = uri or (
        "data:application/octet-stream;base64," + base64.b64encode(binary).decode())
    return json.dumps(doc).encode()


def glb(count=None, node=None):
    doc, binary = gltf_parts(count, node)
    j = json.dumps(doc).encode()
    j += b" " * (-len(j) % 4)
    binary += b"\0" * (-len(binary) % 4)
    total = 12 + 8 + len(j) + 8 + len(binary)
    return (b"glTF" + struct.pack("<II", 2, total) + struct.pack("<I", len(j)) + b"JSON" + j +
            struct.pack("<I", len(binary)) + b"BIN\0" + binary)


def gltf_doc(doc):
    """A glTF document of the cube with doc's keys changed (None removes one)."""
    d, binary = gltf_parts()
    d["buffers"][0]["uri"] = (
        "data:application/octet-stream;base64," + base64.b64encode(binary).decode())
    for k, v in doc.items():
        if v is None:
            d.pop(k, None)
        else:
            d[k] = v
    return json.dumps(d).encode()


def gltf_views(doc_change, blobs):
    """The cube as glTF with buffer views appended, one per blob (4-byte
    aligned); doc_change(doc, first) edits the document, first being the
    first new view's index."""
    d, binary = gltf_parts()
    first = len(d["bufferViews"])
    for data in blobs:
        binary += b"\0" * (-len(binary) % 4)
        d["bufferViews"].append({"buffer": 0, "byteOffset": len(binary), "byteLength": len(data)})
        binary += data
    d["buffers"][0]["byteLength"] = len(binary)
    d["buffers"][0]["uri"] = (
        "data:application/octet-stream;base64," + base64.b64encode(binary).decode())
    doc_change(d, first)
    return json.dumps(d).encode()


def gltf_extra(doc_change, extra):
    """The cube as glTF with buffer views and accessors appended: extra is
    a list of (bytes, accessor dict without bufferView); doc_change(doc,
    first) edits the document, first being the first new accessor's index."""
    def change(d, view):
        first = len(d["accessors"])
        for k, (_, acc) in enumerate(extra):
            d["accessors"].append(dict(acc, bufferView=view + k))
        doc_change(d, first)
    return gltf_views(change, [data for data, _ in extra])


def gltf_morph(node_weights=None):
    """The cube with one morph target moving it by +10 along x; the mesh's
    default weight 1, the node's node_weights when given."""
    delta = b"".join(struct.pack("<3f", 10, 0, 0) for _ in V)

    def change(d, first):
        d["meshes"][0]["primitives"][0]["targets"] = [{"POSITION": first}]
        d["meshes"][0]["weights"] = [1.0]
        if node_weights is not None:
            d["nodes"][0]["weights"] = node_weights
    return gltf_extra(change, [(delta, {"componentType": 5126, "count": len(V), "type": "VEC3"})])


def gltf_skin():
    """The cube skinned to one joint at x = 3 whose inverse bind matrix
    translates by -1: it lands at x = 2. Its node's own translation (100)
    is ignored, as glTF says."""
    joints = b"".join(struct.pack("<4B", 0, 0, 0, 0) for _ in V)
    weights = b"".join(struct.pack("<4f", 1, 0, 0, 0) for _ in V)
    ibm = struct.pack("<16f", 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, -1, 0, 0, 1)

    def change(d, first):
        d["meshes"][0]["primitives"][0]["attributes"].update(
            {"JOINTS_0": first, "WEIGHTS_0": first + 1})
        d["nodes"] = [{"mesh": 0, "skin": 0, "translation": [100, 0, 0]},
                      {"translation": [3, 0, 0]}]
        d["scenes"][0]["nodes"] = [0, 1]
        d["skins"] = [{"joints": [1], "inverseBindMatrices": first + 2}]
    return gltf_extra(change, [
        (joints, {"componentType": 5121, "count": len(V), "type": "VEC4"}),
        (weights, {"componentType": 5126, "count": len(V), "type": "VEC4"}),
        (ibm, {"componentType": 5126, "count": 1, "type": "MAT4"}),
    ])


def sparse(count, view, ctype=5123):
    return {"count": count, "indices": {"bufferView": view, "componentType": ctype},
            "values": {"bufferView": view + 1}}


def gltf_sparse_morph():
    """A morph target as Blender writes a shape key that moves few
    vertices: an accessor with no bufferView (zeros) and sparse values,
    here +10 along x for the four vertices at x = 1: the cube stretched
    to x = 11."""
    moved = [i for i, v in enumerate(V) if v[0] == 1]

    def change(d, first):
        d["accessors"].append({"componentType": 5126, "count": len(V), "type": "VEC3",
                               "sparse": sparse(len(moved), first)})
        d["meshes"][0]["primitives"][0]["targets"] = [{"POSITION": len(d["accessors"]) - 1}]
        d["meshes"][0]["weights"] = [1.0]
    return gltf_views(change, [struct.pack("<%dH" % len(moved), *moved),
                               b"".join(struct.pack("<3f", 10, 0, 0) for _ in moved)])


def gltf_sparse_positions():
    """POSITION with no bufferView, every vertex a sparse value (the cube
    moved by +20 along x), byte indices."""
    def change(d, first):
        d["accessors"][1] = {"componentType": 5126, "count": len(V), "type": "VEC3",
                             "sparse": sparse(len(V), first, 5121)}
    return gltf_views(change, [bytes(range(len(V))),
                               b"".join(struct.pack("<3f", x + 20, y, z) for x, y, z in V)])


def gltf_sparse_ibm(count=2**32 - 1):
    """The skinned cube (gltf_skin) whose inverse bind matrices have no
    bufferView and declare count matrices, the first a sparse value: only
    the joint's matrix may be read (count of them would not fit memory)."""
    joints = b"".join(struct.pack("<4B", 0, 0, 0, 0) for _ in V)
    weights = b"".join(struct.pack("<4f", 1, 0, 0, 0) for _ in V)
    ibm = struct.pack("<16f", 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, -1, 0, 0, 1)

    def change(d, first):
        d["accessors"] += [
            {"bufferView": first, "componentType": 5121, "count": len(V), "type": "VEC4"},
            {"bufferView": first + 1, "componentType": 5126, "count": len(V), "type": "VEC4"},
            {"componentType": 5126, "count": count, "type": "MAT4",
             "sparse": sparse(1, first + 2, 5125)}]
        a = len(d["accessors"])
        d["meshes"][0]["primitives"][0]["attributes"].update(
            {"JOINTS_0": a - 3, "WEIGHTS_0": a - 2})
        d["nodes"] = [{"mesh": 0, "skin": 0}, {"translation": [3, 0, 0]}]
        d["scenes"][0]["nodes"] = [0, 1]
        d["skins"] = [{"joints": [1], "inverseBindMatrices": a - 1}]
    return gltf_views(change, [joints, weights, struct.pack("<I", 0), ibm])


def gltf_zero_huge(count=3 * 10**9):
    """POSITION with no bufferView and no indices declaring count vertices:
    a count nothing backs, 413 by the triangle limit before any read (past
    2^32 - 1, what the importer reads at most, 400)."""
    def change(d, first):
        d["accessors"][1] = {"componentType": 5126, "count": count, "type": "VEC3"}
        del d["meshes"][0]["primitives"][0]["indices"]
    return gltf_views(change, [])


def gltf_skin_short():
    """The skinned cube with JOINTS_0 and WEIGHTS_0 of one element (its
    eight vertices read past them: heap bytes came back in the message)."""
    d = json.loads(gltf_skin())
    for a in d["accessors"][2:4]:
        a["count"] = 1
    return json.dumps(d).encode()


def gltf_skin_many(n):
    """n nodes of the skinned cube on one skin of all n nodes as joints
    (its joints were made again for each node: n^2)."""
    d = json.loads(gltf_skin())
    d["nodes"] = [{"mesh": 0, "skin": 0} for _ in range(n)]
    d["scenes"][0]["nodes"] = list(range(n))
    d["skins"] = [{"joints": list(range(n))}]
    return json.dumps(d).encode()


def gltf_chain(depth):
    """The cube at the end of a chain of depth nested nodes."""
    nodes = [{"children": [k + 1]} for k in range(depth - 1)] + [{"mesh": 0}]
    return gltf_doc({"nodes": nodes})


def glb_instances(n):
    """n nodes, each an instance of the cube (12 triangles each)."""
    doc, binary = gltf_parts()
    doc["nodes"] = [{"mesh": 0, "translation": [2.0 * (k % 100), 2.0 * (k // 100), 0.0]}
                    for k in range(n)]
    doc["scenes"] = [{"nodes": list(range(n))}]
    j = json.dumps(doc, separators=(",", ":")).encode()
    j += b" " * (-len(j) % 4)
    binary += b"\0" * (-len(binary) % 4)
    total = 12 + 8 + len(j) + 8 + len(binary)
    return (b"glTF" + struct.pack("<II", 2, total) + struct.pack("<I", len(j)) + b"JSON" + j +
            struct.pack("<I", len(binary)) + b"BIN\0" + binary)


def glb_primitives(nv, nprim):
    """One accessor of nv vertices and nprim primitives of one triangle each
    over it (its own 3 vertices)."""
    pos = b"".join(struct.pack("<3f", float(i % 1000), float(i // 1000), float(i % 7))
                   for i in range(nv))
    idx = struct.pack("<%dI" % (3 * nprim), *[(3 * p + c) % nv for p in range(nprim)
                                                 for c in range(3)])
    binary = pos + idx
    doc = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
           "nodes": [{"mesh": 0}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1 + p}
                                      for p in range(nprim)]}],
           "buffers": [{"byteLength": len(binary)}],
           "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": len(pos)},
                           {"buffer": 0, "byteOffset": len(pos), "byteLength": len(idx)}],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": nv, "type": "VEC3"}] +
                        [{"bufferView": 1, "byteOffset": 12 * p, "componentType": 5125,
                          "count": 3, "type": "SCALAR"} for p in range(nprim)]}
    j = json.dumps(doc, separators=(",", ":")).encode()
    j += b" " * (-len(j) % 4)
    total = 12 + 8 + len(j) + 8 + len(binary)
    return (b"glTF" + struct.pack("<II", 2, total) + struct.pack("<I", len(j)) + b"JSON" + j +
            struct.pack("<I", len(binary)) + b"BIN\0" + binary)


def obj_quads(head=b""):
    s = head + b"".join(b"v %g %g %g\n" % v for v in V)
    return s + b"".join(b"f %d %d %d %d\n" % tuple(i + 1 for i in q) for q in Q)


def main():
    d = sys.argv[1]
    os.makedirs(d, exist_ok=True)
    moved = {"mesh": 0, "translation": [10, 20, 30], "scale": [2, 2, 2]}
    files = {
        "cube_bin.stl": stl_binary(b"solid cube, a binary STL whose header starts with solid"),
        "cube_ascii.stl": stl_ascii(),
        "cube_bin.ply": ply("binary_little_endian", T),
        "cube_be.ply": ply("binary_big_endian", T),
        "cube_ascii.ply": ply("ascii", Q),
        "cube.gltf": gltf(),
        "cube.glb": glb(node=moved),
        "cube.off": off(),
        # what exporters write too: keywords in capitals, a byte order
        # mark, names in Latin-1, lines of any length
        "cube_upper.stl": stl_ascii().upper(),
        "cube_bom.stl": b"\xef\xbb\xbf" + stl_ascii(),
        "cube_latin1.obj": obj_quads(b"# Exportiert von M\xe4x\ng W\xfcrfel\nusemtl M\xe4t\n"),
        "cube_long.off": off().replace(b"# a cube\n", b"#" + b"x" * 6000 + b"\n").replace(
            b"\n1 1 1\n", b"\n1 1 1" + b" " * 5000 + b"\n"),
        # classic Mac OS line ends (CR alone); vertex colours with alpha
        "cube_cr.obj": obj_quads(b"# made on a Mac\n").replace(b"\n", b"\r"),
        "cube_rgba.obj": obj_quads().replace(b"\nf", b" 0.5 0.25 1 0.75\nf", 1).replace(
            b"\nv", b" 1 0 0 1\nv"),
        # homogeneous vertices (w = 2: each coordinate doubled, then halved)
        # and nOFF's dimension line
        "cube_4.off": off().replace(b"OFF\n", b"4OFF\n").replace(b"\n0 0 0\n", b"\n0 0 0 2\n")
        .replace(b"\n1 1 1\n", b"\n2 2 2 2\n").replace(b"\n1 0 0\n", b"\n2 0 0 2\n")
        .replace(b"\n0 1 0\n", b"\n0 2 0 2\n").replace(b"\n1 1 0\n", b"\n2 2 0 2\n")
        .replace(b"\n0 0 1\n", b"\n0 0 2 2\n").replace(b"\n1 0 1\n", b"\n2 0 2 2\n")
        .replace(b"\n0 1 1\n", b"\n0 2 2 2\n"),
        "cube_n.off": off().replace(b"OFF\n", b"nOFF\n3\n"),
        # binary STL with bytes after the last triangle (some exporters pad
        # or append), with a "solid" header too; ASCII STL whose normals
        # are MSVC's NaN (-1.#IND00) and whose name runs past the 512
        # bytes the sniff sees; ModelNet's OFF header ("OFF8 6 0"); OBJ
        # with the spec's texture map, shell and old patch statements
        "cube_trailing.stl": stl_binary(b"exported by a CAD tool") + b"\0" * 7,
        "cube_trailing_solid.stl": stl_binary() + b"\0\0\x01",
        "cube_ind.stl": stl_ascii().replace(b"solid cube\n", b"solid " + b"c" * 600 + b"\n")
        .replace(b"facet normal 0 0 0", b"facet normal -1.#IND00 -1.#IND00 -1.#IND00"),
        "cube_glued.off": off().replace(b"OFF\n# a cube\n", b"OFF"),
        "cube_maplib.obj": obj_quads(b"maplib a.map\nusemap wood\ncsh -echo\nbzp 1 2\nres 4 4\n"),
        "cube_deep.gltf": gltf_chain(200),
        "cube_morph.gltf": gltf_morph(),
        "cube_morph_node.gltf": gltf_morph([0.5]),
        "cube_skin.gltf": gltf_skin(),
        "cube_sparse_morph.gltf": gltf_sparse_morph(),
        "cube_sparse_pos.gltf": gltf_sparse_positions(),
        "cube_sparse_ibm.gltf": gltf_sparse_ibm(),
        "zero_huge.gltf": gltf_zero_huge(),
        "zero_2e33.gltf": gltf_zero_huge(2**33),
        "skin_short.gltf": gltf_skin_short(),
        "skin_many.gltf": gltf_skin_many(8000),
        "instances.glb": glb_instances(200000),
        "primitives.glb": glb_primitives(400000, 40000),
        # malformed
        "bad.stl": stl_ascii().replace(b"vertex 1 1 1", b"vertex 1 x 1"),
        "bad.ply": ply("ascii", Q).replace(b"property float y", b"property quux y"),
        "bad.gltf": b'{"asset": {"version": "2.0"}, "buffers": [',
        "bad.glb": glb()[:40],
        "bad.off": b"OFF\n8 6 0\n0 0 0\n1 0 0\nzz\n",
        "mode7.gltf": gltf_doc({"meshes": [{"primitives": [
            {"attributes": {"POSITION": 1}, "indices": 0, "mode": 7}]}]}),
        # declared counts that lie
        "lie.stl": stl_binary()[:80] + struct.pack("<I", 4000000000) + stl_binary()[84:],
        "lie.ply": ply("binary_little_endian", T, nverts=2000000000),
        "lie_faces.ply": ply("ascii", Q, nfaces=3000000000),
        "lie.gltf": gltf(count=1000000000),
        "lie.glb": glb(count=1000000000),
        "lie.off": off(nv=8, nf=2000000000),
        # a face naming one vertex twice (its fan folds onto itself), as OBJ
        "repeat.off": b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n4 0 1 2 1\n",
        "repeat.ply": ply("ascii", Q).replace(b"\n4 0 2 3 1\n", b"\n4 0 2 3 2\n", 1),
        "external.gltf": gltf(uri="../../../etc/passwd"),
        # data: URIs the reader does not decode: said so (the first was
        # tinygltf's "FS callback[s] not set", the second "external file")
        "data_no_type.gltf": gltf(uri="data:;base64,AAAA"),
        "data_upper.gltf": gltf(uri="DATA:application/octet-stream;base64,AAAA"),
        "too_deep.gltf": gltf_chain(300),
        "draco.gltf": gltf_doc({"extensionsUsed": ["KHR_draco_mesh_compression"],
                                "extensionsRequired": ["KHR_draco_mesh_compression"]}),
        "short_matrix.gltf": gltf_doc({"nodes": [{"mesh": 0, "matrix": [1, 0, 0]}]}),
        "zero_rotation.gltf": gltf_doc({"nodes": [{"mesh": 0, "rotation": [0, 0, 0, 0]}]}),
        # counts too small, read out of step; an index that is not one
        "short.off": off(nf=5),
        "float_index.off": off().replace(b"\n4 1 3 7 5\n", b"\n4 1 3 7 5.5\n"),
        "n4.off": off().replace(b"OFF\n", b"nOFF\n4\n"),
        "w0.off": off().replace(b"OFF\n", b"4OFF\n").replace(b"\n0 0 0\n", b"\n0 0 0 0\n")
        .replace(b"\n1 1 1\n", b"\n1 1 1 1\n").replace(b"\n1 0 0\n", b"\n1 0 0 1\n")
        .replace(b"\n0 1 0\n", b"\n0 1 0 1\n").replace(b"\n1 1 0\n", b"\n1 1 0 1\n")
        .replace(b"\n0 0 1\n", b"\n0 0 1 1\n").replace(b"\n1 0 1\n", b"\n1 0 1 1\n")
        .replace(b"\n0 1 1\n", b"\n0 1 1 1\n"),
        "short.ply": ply("ascii", Q, nverts=7),
        "trailing.ply": ply("binary_little_endian", T) + b"\x01\x02\x03\x04",
        "cycle.glb": glb(node={"mesh": 0, "children": [0]}),
        "call.obj": obj_quads(b"call other.obj\n"),
        "trailing_short.stl": stl_binary()[:-1],
    }
    for name, data in files.items():
        with open(os.path.join(d, name), "wb") as f:
            f.write(data)


if __name__ == "__main__":
    main()
