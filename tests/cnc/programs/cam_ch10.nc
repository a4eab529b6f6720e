%
O9050 (NC BOOK CH.10 EXAMPLE 2 - ECCENTRIC CAM, XZ PLANE)
(Transcribed to this controller's dialect: I K incremental from the arc start, the)
(Table 5 speed code S72 written as S400 rpm, the cutter centre path without G42,)
(F1000 instead of F200 to keep the test short, end point X19.9 where the book's)
(19.85 does not lie on the arc: see the seed's radius check)
N5 G10 L2 P1 X-300. Y-200. Z-300.
N10 G21 G90 G18 G54 G40
N20 G0 X19.85 Z20. S400 M3
N30 Y-1.
N40 M8
N50 G1 Z2. F1000
N60 G3 X18.225 Z-2.106 I-6. K0
N70 X1.079 Z-9.972 I-18.225 K17.106
N80 X1.072 Z19.971 I0.921 K14.972
N90 X19.9 Z2. I-1.072 K-19.971
N100 G1 Z0.
N110 G0 Y50. M9
N120 M5
N130 M30
%
