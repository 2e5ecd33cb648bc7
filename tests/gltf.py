"""Binary glTF (GLB) files written as the glTF 2.0 specification lays them out, for the readers' tests: one mesh
of float positions and unsigned-int triangles, with per-vertex colours (COLOR_0) or texture coordinates
(TEXCOORD_0) into one embedded PNG image, as phone scanning apps export."""
import io
import json
import struct

import numpy as np

FLOAT, UINT = 5126, 5125
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963


def write_glb(path, vertices, faces, colours=None, uv=None, image=None, places=((0.0, 0.0, 0.0),)) -> None:
    """vertices (N, 3); faces (M, 3); colours (N, 3) in 0..1; uv (N, 2), glTF's (0, 0) the image's top left,
    with `image` (H, W, 3) uint8; the mesh placed once per translation in `places` (a node each)."""
    from PIL import Image

    chunks, views, accessors = [], [], []

    def add(data: bytes, target=None, accessor=None):
        views.append({"buffer": 0, "byteOffset": sum(map(len, chunks)), "byteLength": len(data)}
                     | ({"target": target} if target else {}))
        chunks.append(data + b"\0" * (-len(data) % 4))
        if accessor is None:
            return len(views) - 1
        accessors.append({"bufferView": len(views) - 1} | accessor)
        return len(accessors) - 1

    V = np.asarray(vertices, np.float32)
    attributes = {"POSITION": add(V.tobytes(), ARRAY_BUFFER, {"componentType": FLOAT, "count": len(V), "type": "VEC3",
                                                               "min": V.min(0).tolist(), "max": V.max(0).tolist()})}
    F = np.asarray(faces, np.uint32).ravel()
    primitive = {"attributes": attributes,
                 "indices": add(F.tobytes(), ELEMENT_ARRAY_BUFFER, {"componentType": UINT, "count": len(F),
                                                                    "type": "SCALAR"})}
    gltf = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": list(range(len(places)))}],
            "nodes": [{"mesh": 0, "translation": [float(v) for v in t]} for t in places],
            "meshes": [{"primitives": [primitive]}]}
    if colours is not None:
        attributes["COLOR_0"] = add(np.asarray(colours, np.float32).tobytes(), ARRAY_BUFFER,
                                    {"componentType": FLOAT, "count": len(V), "type": "VEC3"})
    if uv is not None:
        attributes["TEXCOORD_0"] = add(np.asarray(uv, np.float32).tobytes(), ARRAY_BUFFER,
                                       {"componentType": FLOAT, "count": len(V), "type": "VEC2"})
        png = io.BytesIO()
        Image.fromarray(image).save(png, format="PNG")
        gltf |= {"images": [{"bufferView": add(png.getvalue()), "mimeType": "image/png"}], "textures": [{"source": 0}],
                 "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]}
        primitive["material"] = 0
    binary = b"".join(chunks)
    gltf |= {"accessors": accessors, "bufferViews": views, "buffers": [{"byteLength": len(binary)}]}
    text = json.dumps(gltf).encode()
    text += b" " * (-len(text) % 4)
    with open(path, "wb") as fh:
        fh.write(struct.pack("<4sII", b"glTF", 2, 12 + 8 + len(text) + 8 + len(binary)))
        fh.write(struct.pack("<I4s", len(text), b"JSON") + text)
        fh.write(struct.pack("<I4s", len(binary), b"BIN\0") + binary)
