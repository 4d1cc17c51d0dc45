(conform sample job: three circles of short chords at a high feed - a sender must)
(supply about 180 vectors/s to keep the queue fed)
G21 G90 G17
G0 X0 Y0
F6000
G1 X10 Y0
G3 X10 Y0 I-10 J0
G3 X10 Y0 I-10 J0
G3 X10 Y0 I-10 J0
G1 X0 Y0
