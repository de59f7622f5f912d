1 ' melfa_pick.prg -- bin picking with binpick's vision server, Mitsubishi MELFA (MELFA-BASIC V).
2 ' Scans the bin, asks binpick for the next pick, moves through the four waypoints it sends,
3 ' grips, drops the part and reports the result, until the bin is empty.
4 ' Protocol version 1, see docs/protocol.md: one ASCII line per message (CR ends a request);
5 ' a reply is "(numbers)" and, for an error only, " text" after it.
6 ' Brand melfa ([server] brand = "melfa"): a pose is X, Y, Z in mm and A, B, C in degrees,
7 ' R = Rz(C)*Ry(B)*Rx(A), as a MELFA POSE without its flags: the FLANGE (Tool P_NTool)
8 ' in the robot base frame (Base P_NBase), the frame binpick's calibration was solved in.
9 ' COM2: is an Ethernet client to binpick, set in the controller parameters (EDIT):
10 '   NETIP = the robot's own address; COMDEV element 2 (COM2:) = OPT11;
11 '   NETMODE(1) = 0 (client); NETHSTIP(1) = "127.0.0.1", the PC running binpick serve;
12 '   NETPORT(2) = 50100 (the port of OPT11); CPRCE11 = 2 (data link: Open/Print/Input);
13 '   MELFA ends a Print line with CR, which binpick takes as the end of a request.
14 ' binpick ends its replies with CR LF: Input # ends at the CR. Check how long a string
15 ' (CRP$) your controller holds: a NEXT reply is about 250 characters.
16 ' Written from the MELFA-BASIC V manual; not run on a controller. Also check that your
17 ' version allows assigning a position's components (PW.X = ...) and Print of several items.
18 Dim MV(30)
19 ' the last reply's numbers: MV(1) the code
20 Tool P_NTool
21 ' binpick sends flange poses: no tool frame (EDIT LoadSet for the gripper's load)
22 Base P_NBase
23 ' EDIT: scan pose (the cell file's scan_pose) and drop pose (its drop_pose), flange
24 PSCAN = (400.00, 0.00, 620.00, 180.00, 0.00, 180.00)(7, 0)
25 PDROP = (100.00, -450.00, 400.00, 180.00, 0.00, 180.00)(7, 0)
26 Open "COM2:" As #1
27 ' HELLO 1 -> (code, version, brand id, n): brand 6 is melfa, with 6 numbers per pose
28 Print #1, "HELLO 1"
29 MN = 4
30 GoSub *ASK
31 If (MV(1) <> 0) Or (MV(3) <> 6) Or (MV(4) <> 6) Then GoTo *FIN
32 HOpen 1
33 *SCAN
34 ' 1. Stand still at the scan pose, SCAN with the flange pose; no motion until the reply
35 Mov PSCAN
36 Dly 0.2
37 PHERE = P_Fbc
38 ' P_Fbc.A/B/C are radians: binpick takes degrees
39 Print #1, "SCAN ", PHERE.X, PHERE.Y, PHERE.Z, Deg(PHERE.A), Deg(PHERE.B), Deg(PHERE.C)
40 MN = 4
41 GoSub *ASK
42 If MV(1) <> 0 Then GoTo *FIN
43 ' 2. NEXT -> (code, pick id, part, confidence, decided, opening mm, above, approach, grasp, lift)
44 Print #1, "NEXT"
45 MN = 30
46 GoSub *ASK
47 ' 10: the bin is empty; 11: nothing pickable from this scan (scan elsewhere, or clear by hand)
48 If MV(1) <> 0 Then GoTo *FIN
49 MPICK = MV(2)
50 ' MV(6): the finger opening in mm, for a width-controlled hand (EDIT)
51 MK = 7
52 GoSub *POSE
53 PAB = PW
54 MK = 13
55 GoSub *POSE
56 PAP = PW
57 MK = 19
58 GoSub *POSE
59 PGR = PW
60 MK = 25
61 GoSub *POSE
62 PLF = PW
63 ' 3. Jointly to above, linearly to approach and grasp, close, linearly to lift, drop
64 HOpen 1
65 Mov PAB
66 Mvs PAP
67 Mvs PGR
68 HClose 1
69 Dly 0.5
70 MHELD = 0
71 ' EDIT: the hand's "part held" input
72 If M_In(900) = 1 Then MHELD = 1
73 Mvs PLF
74 If MHELD = 1 Then Mov PDROP
75 HOpen 1
76 Dly 0.3
77 ' 4. RESULT pick_id 1|0 -> (code, pick id, picks reported, parts held)
78 Print #1, "RESULT ", MPICK, MHELD
79 MN = 4
80 GoSub *ASK
81 If MV(1) = 0 Then GoTo *SCAN
82 *FIN
83 ' MCODE and CTX$ keep the code and text that stopped the loop (see the variable monitor)
84 MCODE = MV(1)
85 Print #1, "BYE"
86 MN = 1
87 GoSub *ASK
88 Close #1
89 If MCODE <> 10 Then Error 9100
90 End
91 '
92 *POSE
93 ' PW = the pose at MV(MK..MK+5); its flags (arm configuration) are the scan pose's
94 PW = PHERE
95 PW.X = MV(MK)
96 PW.Y = MV(MK + 1)
97 PW.Z = MV(MK + 2)
98 PW.A = Rad(MV(MK + 3))
99 PW.B = Rad(MV(MK + 4))
100 PW.C = Rad(MV(MK + 5))
101 Return
102 '
103 *ASK
104 ' The reply to the request just printed: its MN numbers into MV(1..MN), the text into CTX$.
105 ' "(" opens the numbers, "," ends one, ")" ends the last; a "(21) busy" reply has only one.
106 ' StrPos is MELFA's substring search (InStr in other BASICs); it returns 0 when not found.
107 For MI = 1 To MN
108 MV(MI) = 0
109 Next MI
110 CTX$ = ""
111 Input #1, CRP$
112 MP = StrPos(CRP$, "(")
113 If MP = 0 Then GoTo *ASKBAD
114 CRP$ = Mid$(CRP$, MP + 1, Len(CRP$) - MP)
115 MF = 0
116 *ASKFLD
117 MC = StrPos(CRP$, ",")
118 ME = StrPos(CRP$, ")")
119 If ME = 0 Then GoTo *ASKBAD
120 If (MC = 0) Or (MC > ME) Then MC = ME
121 MF = MF + 1
122 If MF <= MN Then MV(MF) = Val(Left$(CRP$, MC - 1))
123 If MC = ME Then GoTo *ASKEND
124 CRP$ = Mid$(CRP$, MC + 1, Len(CRP$) - MC)
125 GoTo *ASKFLD
126 *ASKEND
127 If Len(CRP$) > ME Then CTX$ = Mid$(CRP$, ME + 1, Len(CRP$) - ME)
128 Return
129 *ASKBAD
130 MV(1) = -1
131 Return
