NAME        
ROWS
 N  Obj     
 E  r0      
 E  r1      
 E  r2      
 E  r3      
 E  r4      
 E  r5      
 L  r6      
 L  r7      
 L  r8      
 L  r9      
 L  r10     
 G  r11     
 G  r12     
 G  r13     
 G  r14     
 G  r15     
 L  r16     
 L  r17     
 L  r18     
 L  r19     
 L  r20     
 L  r21     
 L  r22     
 L  r23     
 L  r24     
 E  r25     
 E  r26     
 E  r27     
 E  r28     
 L  r29     
 L  r30     
 L  r31     
 L  r32     
 L  r33     
 E  r34     
 E  r35     
 E  r36     
 E  r37     
 G  r38     
COLUMNS
    c0        r0        -1
    c0        r6        1
    c0        r21       1
    c0        r38       1
    c1        r1        -1
    c1        r38       1
    c2        r2        -1
    c2        r7        1
    c2        r22       1
    c2        r38       1
    c3        r0        1
    c3        r1        -1
    c3        r16       1
    c4        r0        1
    c4        r2        -1
    c4        r8        1
    c4        r17       1
    c4        r23       1
    c5        r0        1
    c5        r9        1
    c5        r18       1
    c6        r1        1
    c6        r3        -1
    c7        r1        1
    c7        r4        -1
    c8        r1        1
    c9        r0        -1
    c9        r2        1
    c9        r10       1
    c9        r19       1
    c9        r24       1
    c10       r1        -1
    c10       r2        1
    c10       r20       1
    c11       r1        -1
    c11       r3        1
    c12       r3        1
    c12       r4        -1
    c13       r3        1
    c13       r5        -1
    c14       r1        -1
    c14       r4        1
    c15       r3        -1
    c15       r4        1
    c16       r4        1
    c17       r4        1
    c17       r5        -1
    c18       r1        -1
    c18       r5        1
    c19       r3        -1
    c19       r5        1
    c20       r4        -1
    c20       r5        1
    MARK0000  'MARKER'                 'INTORG'
    c21       Obj       1
    c21       r6        1
    c21       r11       1
    c21       r29       1
    c22       Obj       1
    c22       r7        1
    c22       r12       1
    c22       r30       1
    c23       Obj       1
    c23       r8        1
    c23       r13       1
    c23       r31       1
    c24       Obj       1
    c24       r9        1
    c24       r14       1
    c24       r32       1
    c25       Obj       1
    c25       r10       1
    c25       r15       1
    c25       r33       1
    MARK0001  'MARKER'                 'INTEND'
    c26       r11       1
    c26       r13       -1
    c26       r14       -1
    c26       r15       1
    c26       r16       -1
    c26       r17       -1
    c26       r18       -1
    c26       r21       -1
    c26       r24       -1
    c27       r12       1
    c27       r13       1
    c27       r15       -1
    c27       r19       -1
    c27       r20       -1
    c27       r22       -1
    c27       r23       -1
    c28       r25       1
    c28       r26       -1
    c28       r29       1
    c29       r25       1
    c29       r27       -1
    c30       r25       1
    c30       r28       -1
    c30       r30       1
    c31       r25       -1
    c31       r26       1
    c32       r26       1
    c32       r27       -1
    c33       r26       1
    c33       r28       -1
    c33       r31       1
    c34       r26       1
    c34       r32       1
    c35       r25       -1
    c35       r27       1
    c36       r26       -1
    c36       r27       1
    c37       r27       1
    c38       r25       -1
    c38       r28       1
    c39       r26       -1
    c39       r28       1
    c39       r33       1
    c40       r27       -1
    c40       r28       1
    c41       r34       1
    c41       r35       -1
    c42       r34       1
    c42       r36       -1
    c43       r34       1
    c43       r37       -1
    c44       r34       -1
    c44       r35       1
    c45       r35       1
    c45       r36       -1
    c46       r35       1
    c46       r37       -1
    c47       r35       1
    c48       r34       -1
    c48       r36       1
    c49       r35       -1
    c49       r36       1
    c50       r36       1
    c51       r34       -1
    c51       r37       1
    c52       r35       -1
    c52       r37       1
    c53       r36       -1
    c53       r37       1
RHS
    RHS_V     r6        1
    RHS_V     r7        1
    RHS_V     r8        1
    RHS_V     r9        1
    RHS_V     r10       1
    RHS_V     r11       1
    RHS_V     r12       1
    RHS_V     r25       1
    RHS_V     r29       1
    RHS_V     r30       1
    RHS_V     r31       1
    RHS_V     r32       1
    RHS_V     r33       1
    RHS_V     r36       1
    RHS_V     r38       1.5
BOUNDS
 UP BOUND     c0        1
 UP BOUND     c1        1
 UP BOUND     c2        1
 UP BOUND     c3        1
 UP BOUND     c4        1
 UP BOUND     c5        1
 UP BOUND     c6        1
 UP BOUND     c7        1
 UP BOUND     c8        1
 UP BOUND     c9        1
 UP BOUND     c10       1
 UP BOUND     c11       1
 UP BOUND     c12       1
 UP BOUND     c13       1
 UP BOUND     c14       1
 UP BOUND     c15       1
 UP BOUND     c16       1
 UP BOUND     c17       1
 UP BOUND     c18       1
 UP BOUND     c19       1
 UP BOUND     c20       1
 BV BOUND     c21     
 BV BOUND     c22     
 BV BOUND     c23     
 BV BOUND     c24     
 BV BOUND     c25     
 UP BOUND     c26       1
 UP BOUND     c27       1
 UP BOUND     c28       1
 UP BOUND     c29       1
 UP BOUND     c30       1
 UP BOUND     c31       1
 UP BOUND     c32       1
 UP BOUND     c33       1
 UP BOUND     c34       1
 UP BOUND     c35       1
 UP BOUND     c36       1
 UP BOUND     c37       1
 UP BOUND     c38       1
 UP BOUND     c39       1
 UP BOUND     c40       1
 UP BOUND     c41       1
 UP BOUND     c42       1
 UP BOUND     c43       1
 UP BOUND     c44       1
 UP BOUND     c45       1
 UP BOUND     c46       1
 UP BOUND     c47       1
 UP BOUND     c48       1
 UP BOUND     c49       1
 UP BOUND     c50       1
 UP BOUND     c51       1
 UP BOUND     c52       1
 UP BOUND     c53       1
ENDATA
