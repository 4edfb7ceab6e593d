#!/usr/bin/env python3
"""Writes a glTF 2.0 file placing one OBJ mesh SIDE x SIDE times (node i rotated
0.4*i radians about y, on a lattice of 1.2 times the mesh size, as
examples/instances places its copies): a two-level scene for
`kdtrace trace --two-level` and tools/shader-instructions (docs/EMBEDDING.md).

Usage: tools/gltf-grid.py SCENE.obj SIDE OUT.gltf
"""
import base64
import json
import math
import struct
import sys

if len(sys.argv) != 4:
    sys.exit(__doc__)
obj, side, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
V=[]; F=[]
for line in open(obj):
    p=line.split()
    if not p: continue
    if p[0]=='v': V.append(tuple(map(float,p[1:4])))
    elif p[0]=='f':
        idx=[int(x.split('/')[0]) for x in p[1:]]
        idx=[i-1 if i>0 else len(V)+i for i in idx]
        for k in range(1,len(idx)-1): F.append((idx[0],idx[k],idx[k+1]))
mn=[min(v[i] for v in V) for i in range(3)]; mx=[max(v[i] for v in V) for i in range(3)]
size=max(mx[i]-mn[i] for i in range(3)); c=[(mn[i]+mx[i])/2 for i in range(3)]
pos=b''.join(struct.pack('<3f',*v) for v in V)
ind=b''.join(struct.pack('<3I',*f) for f in F)
buf=pos+ind
nodes=[]
for i in range(side*side):
    a=0.4*i
    q=[0,math.sin(a/2),0,math.cos(a/2)]
    t=[(i%side)*size*1.2-c[0],(i//side)*size*1.2-c[1],-c[2]]
    nodes.append({"mesh":0,"rotation":q,"translation":t})
g={"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":list(range(len(nodes)))}],"nodes":nodes,
 "meshes":[{"primitives":[{"attributes":{"POSITION":0},"indices":1}]}],
 "buffers":[{"byteLength":len(buf),"uri":"data:application/octet-stream;base64,"+base64.b64encode(buf).decode()}],
 "bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":len(pos)},{"buffer":0,"byteOffset":len(pos),"byteLength":len(ind)}],
 "accessors":[{"bufferView":0,"componentType":5126,"count":len(V),"type":"VEC3","min":mn,"max":mx},
              {"bufferView":1,"componentType":5125,"count":3*len(F),"type":"SCALAR"}]}
json.dump(g,open(out,'w'))
