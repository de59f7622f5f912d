MODULE BinpickPick
    ! abb_pick.mod -- bin picking with binpick's vision server, for an ABB arm (RAPID).
    !
    ! Scans the bin, asks binpick for the next pick, moves through the four waypoints it sends,
    ! grips, drops the part and reports the result, until the bin is empty. Protocol version 1,
    ! see docs/protocol.md: one ASCII line per message (a request ends with LF, a reply with CR LF); a reply is "(numbers)" and,
    ! for an error only, " text" after it.
    ! Brand `abb` ([server] brand = "abb"): a pose is x, y, z in mm and the quaternion q1..q4 (q1 the
    ! scalar, as RAPID's orient), the FLANGE (tool0) in wobj0 (the world frame: it must be the frame
    ! binpick's hand-eye calibration was solved in, i.e. the robot base unless your base frame moved).
    ! Needs the PC Interface / Socket Messaging option. Written from the RAPID reference manual;
    ! not run on a controller. Check SocketReceive's limits on your RobotWare version.

    CONST string SERVER_IP := "127.0.0.1";   ! EDIT: the PC running `binpick serve`
    CONST num SERVER_PORT := 50100;          ! EDIT: [server] port
    CONST num SCAN_TIMEOUT := 60;            ! s: a SCAN sweeps the laser
    ! EDIT: the scan pose (the cell file's scan_pose) and the drop pose (its drop_pose), flange, wobj0.
    CONST robtarget pScan := [[400,0,620],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
    CONST robtarget pDrop := [[100,-450,400],[0,0,1,0],[-1,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
    ! EDIT: the gripper's load with the TCP left at the flange (binpick sends flange poses).
    PERS tooldata tFlange := [TRUE,[[0,0,0],[1,0,0,0]],[1.0,[0,0,60],[1,0,0,0],0,0,0]];

    VAR socketdev sock;
    VAR num reply{34};       ! the last reply's numbers: 6 + 4 poses x 7 for NEXT
    VAR string chunk := "";  ! received text not yet parsed (a RAPID string holds at most 80 chars)
    VAR num pos := 1;        ! next character of chunk to parse
    VAR string text := "";   ! an error reply's text (its first 60 characters)

    ! Sends one request line (ended with LF) and reads its reply of n numbers into reply{}.
    ! A reply can be about 310 characters, so it is parsed field by field from 80-character receives.
    ! Returns the reply code. A reply shorter than n (e.g. "(21) busy") leaves the rest at 0.
    FUNC num Ask(string request, num n, num timeout)
        VAR string tok := "";
        VAR string c;
        VAR num k := 0;
        VAR num d;
        VAR bool closed := FALSE;
        VAR bool lineEnd := FALSE;
        SocketSend sock \Str:=request + "\0A";
        FOR i FROM 1 TO n DO
            reply{i} := 0;
        ENDFOR
        chunk := "";
        pos := 1;
        text := "";
        ! The numbers: "(" opens them, "," ends one, ")" ends the last.
        WHILE NOT closed DO
            IF pos > StrLen(chunk) Refill timeout;
            d := StrFind(chunk, pos, "(,)");
            IF d > pos tok := tok + StrPart(chunk, pos, d - pos);
            IF d <= StrLen(chunk) THEN
                c := StrPart(chunk, d, 1);
                IF c <> "(" THEN
                    k := k + 1;
                    IF k <= n THEN
                        IF NOT StrToVal(tok, reply{k}) reply{k} := 0;
                    ENDIF
                    closed := c = ")";
                ENDIF
                tok := "";
            ENDIF
            pos := d + 1;
        ENDWHILE
        ! The rest of the line, up to its LF (after the CR): empty after a success, " text" after an error.
        WHILE NOT lineEnd DO
            IF pos > StrLen(chunk) Refill 5;
            d := StrFind(chunk, pos, "\0A");
            KeepText d;
            lineEnd := d <= StrLen(chunk);
            pos := d + 1;
        ENDWHILE
        IF reply{1} <> 0 THEN
            TPWrite "binpick reply code " \Num:=reply{1};
            TPWrite text;
        ENDIF
        RETURN reply{1};
    ENDFUNC

    ! Receives the next piece of the reply (at most 80 characters) into chunk.
    PROC Refill(num timeout)
        SocketReceive sock \Str:=chunk \Time:=timeout;
        pos := 1;
    ENDPROC

    ! Keeps chunk's characters from pos up to (not including) e in text, 60 characters at most.
    PROC KeepText(num e)
        VAR num len;
        len := e - pos;
        IF len > 60 - StrLen(text) len := 60 - StrLen(text);
        IF len > 0 text := text + StrPart(chunk, pos, len);
    ENDPROC

    ! The pose at reply{k..k+6} as a robtarget; robconf and extax are the scan pose's.
    FUNC robtarget PoseAt(num k, robtarget like)
        VAR robtarget p;
        p := like;
        p.trans := [reply{k}, reply{k+1}, reply{k+2}];
        p.rot := NOrient([reply{k+3}, reply{k+4}, reply{k+5}, reply{k+6}]);
        RETURN p;
    ENDFUNC

    PROC main()
        VAR robtarget here;
        VAR num code;
        VAR num pickId;
        VAR bool held;
        ConfJ \Off;   ! let the controller choose the arm configuration nearest to the last one
        ConfL \Off;
        SetDO doGripClose, 0;   ! EDIT: the gripper's close output
        SocketCreate sock;
        SocketConnect sock, SERVER_IP, SERVER_PORT \Time:=5;
        ! HELLO 1 -> (code, version, brand id, n): brand 2 is abb, with 7 numbers per pose.
        IF Ask("HELLO 1", 4, 5) <> 0 OR reply{3} <> 2 OR reply{4} <> 7 THEN
            TPWrite "binpick: HELLO refused or the server's brand is not abb";
            EXIT;
        ENDIF
        WHILE TRUE DO
            ! 1. Stop at the scan pose; SCAN with the flange pose; no motion until the reply.
            MoveJ pScan, v500, fine, tFlange \WObj:=wobj0;
            WaitTime 0.2;
            here := CRobT(\Tool:=tFlange \WObj:=wobj0);   ! tFlange is tool0 with a load: the flange pose
            SocketSend sock \Str:="SCAN " + NumToStr(here.trans.x, 3) + "," + NumToStr(here.trans.y, 3) + "," + NumToStr(here.trans.z, 3) + ",";
            code := Ask(NumToStr(here.rot.q1, 6) + "," + NumToStr(here.rot.q2, 6) + "," + NumToStr(here.rot.q3, 6) + "," + NumToStr(here.rot.q4, 6), 4, SCAN_TIMEOUT);
            IF code <> 0 GOTO done;
            ! 2. NEXT -> (code, pick id, part, confidence, decided, opening, above, approach, grasp, lift)
            code := Ask("NEXT", 34, 30);
            IF code = 10 TPWrite "binpick: the bin is empty";
            IF code <> 0 GOTO done;   ! 11: nothing pickable from this scan (scan elsewhere or clear by hand)
            pickId := reply{2};
            ! reply{6}: the finger opening (mm), for a width-controlled gripper (EDIT)
            ! 3. Jointly to above, linearly to approach and grasp, close, linearly to lift, drop.
            SetDO doGripClose, 0;
            MoveJ PoseAt(7, here), v500, z10, tFlange \WObj:=wobj0;
            MoveL PoseAt(14, here), v200, fine, tFlange \WObj:=wobj0;
            MoveL PoseAt(21, here), v50, fine, tFlange \WObj:=wobj0;
            SetDO doGripClose, 1;
            WaitTime 0.5;
            held := DInput(diPartHeld) = 1;   ! EDIT: the gripper's "part held" input
            MoveL PoseAt(28, here), v200, fine, tFlange \WObj:=wobj0;
            IF held THEN
                MoveJ pDrop, v500, fine, tFlange \WObj:=wobj0;
            ENDIF
            SetDO doGripClose, 0;
            WaitTime 0.3;
            ! 4. RESULT id 1|0 -> (code, pick id, picks reported, parts held)
            IF held THEN
                code := Ask("RESULT " + NumToStr(pickId, 0) + " 1", 4, 5);
            ELSE
                code := Ask("RESULT " + NumToStr(pickId, 0) + " 0", 4, 5);
            ENDIF
            IF code <> 0 GOTO done;
        ENDWHILE
        done:
        code := Ask("BYE", 1, 5);
        SocketClose sock;
    ERROR
        IF ERRNO = ERR_SOCK_TIMEOUT TPWrite "binpick: no reply in time";
        IF ERRNO = ERR_SOCK_CLOSED TPWrite "binpick: the connection closed";
        SocketClose sock;
        EXIT;
    ENDPROC
ENDMODULE
