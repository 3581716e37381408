"""Tiny well-formed motion files with hand-computable answers: the loaders' tests check them,
the fuzzer starts from them."""

TINY_BVH = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Chest
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 5 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.5
0 100 0 0 0 0 0 0 0
20 100 0 0 0 0 90 0 0
"""

TINY_ASF = """:version 1.10
:name tiny
:units
  mass 1.0
  length 1.0
  angle deg
:root
   order TX TY TZ RX RY RZ
   axis XYZ
   position 0 0 0
   orientation 0 0 0
:bonedata
  begin
     id 1
     name a
     direction 1 0 0
     length 10
     axis 0 0 0 XYZ
    dof rz
  end
  begin
     id 2
     name b
     direction 0 1 0
     length 10
     axis 0 0 90 XYZ
    dof rx
  end
  begin
     id 3
     name c
     direction 0 1 0
     length 10
     axis 0 0 0 XYZ
  end
:hierarchy
  begin
    root a
    a b
    b c
  end
"""

TINY_AMC = """:FULLY-SPECIFIED
:DEGREES
1
root 0 0 0 0 0 0
a 0
b 0
2
root 0 0 0 0 0 0
a 90
b 0
3
root 0 0 0 0 0 0
a 0
b 90
"""
