%
O0300 (PROGRAM WITH ERRORS FOR fmscell nc check)
G0 X-10 Y-10
G1 X-20
G5 X-1
G0 X-1 E2 (unknown address)
#0=1 (MACRO B: #0 IS READ ONLY)
G1 X-30 F100 (unterminated comment
M30
%
