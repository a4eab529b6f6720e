"""G code numbers as the lexer gives them (int(10 x value): G1 -> 10, G54.1 -> 541), M codes.

The handlers and the interpreter's modal state compare against these names, never against
bare numbers; tests/cnc/test_interp_code_table.py checks each against the code table.
"""

G0, G1, G2, G3 = 0, 10, 20, 30
G17, G18, G19 = 170, 180, 190
G20, G21 = 200, 210
G28, G30, G31 = 280, 300, 310
G53 = 530
G40, G41, G42 = 400, 410, 420
G43, G44, G49 = 430, 440, 490
G54, G54_1 = 540, 541
G61, G64 = 610, 640
G12, G13 = 120, 130
G16, G50, G50_1, G69 = 160, 500, 501, 690
G73, G74, G76, G80 = 730, 740, 760, 800
G81, G82, G83, G84, G85, G86, G87, G88, G89 = 810, 820, 830, 840, 850, 860, 870, 880, 890
G90, G90_1, G91 = 900, 901, 910
G95, G96 = 950, 960
G98, G99 = 980, 990  # mill: return level; lathe: feed per minute / per revolution
M7, M8, M9 = 7, 8, 9
M7_M8 = 78  # M7 and M8 in one block (both coolants)
