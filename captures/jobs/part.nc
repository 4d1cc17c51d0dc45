(conform sample job: a plate outline with rounded corners, a slot and a circle)
G21 G90 G17
G0 X0 Y0
F1500
G1 X40 Y0
G3 X50 Y10 I0 J10
G1 X50 Y30
G3 X40 Y40 I-10 J0
G1 X10 Y40
G1 X0 Y30
G1 X0 Y0
(sharp zig-zag: junctions that must stop or slow)
G1 X5 Y5
G1 X10 Y0
G1 X15 Y5
G1 X20 Y0
(a circle of short chords: many small vectors)
F2400
G0 X25 Y20
G2 X25 Y20 I5 J0
G2 X25 Y20 I5 J0
G1 X30 Y20
G0 X0 Y0
