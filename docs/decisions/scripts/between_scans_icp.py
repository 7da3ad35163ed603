"""Prototype (decision 0014, "The short relations of ACES and MIT CSAIL
are odometry on a 5 cm lattice"): between two processed scans, chain
scan-to-scan ICP between every pair of consecutive scans instead of the
odometry, and spread the gap left at the next processed pose linearly,
as `between_scans = "interpolate"` spreads the odometry's.

Analysis only; squall does not run it and CI does not need it (python3
with numpy and scipy; it borrows the ICP of smoother_prototype.py
beside it). Usage:

  squall slam --log LOG.clf --seed 1 --out run
  python3 between_scans_icp.py LOG.clf run/trajectory.tum out.tum [GATE]
  squall eval --trajectory out.tum --relations LOG.relations

GATE (default 1000, every match kept): a match is used only where it
differs from the odometry's step by less than GATE times (1 cm + 10% of
the step) in position and (5 mrad + 10% of the turn) in heading.
"""
import sys, math, numpy as np
import os
sys.path.insert(0,os.path.dirname(os.path.abspath(__file__)))
import smoother_prototype as sp
clf,tum,outp=sys.argv[1:4]; gate=float(sys.argv[4]) if len(sys.argv)>4 else 1000.0
odo=sp.load_odo(clf); sc=sp.load_scans(clf); tr=sp.load_tum(tum)
ts=sorted(t for t in tr if t in odo and t in sc)
P=set(sp.gate_stamps(odo,ts))
inc=[]; used=0
for a,b in zip(ts,ts[1:]):
    g=sp.rel(odo[a],odo[b])
    d=math.hypot(g[0],g[1])
    m=sp.icp_pl(sc[b],sc[a],tuple(g),iters=15)
    # odometry's plausible error for this step: 5 cm + 10% of the distance, 0.02 rad + 10% of turn
    if m is not None:
        m=np.array(m); e=m-g
        if math.hypot(e[0],e[1])<gate*(0.01+0.1*d) and abs(e[2])<gate*(0.005+0.1*abs(g[2])):
            g=m; used+=1
    inc.append(g)
print("icp used", used, "of", len(inc), file=sys.stderr)
out={}
i=0
while i<len(ts):
    # find next processed
    j=i+1
    while j<len(ts) and ts[j] not in P: j+=1
    out[ts[i]]=tr[ts[i]]
    if j>=len(ts):
        # tail: chain
        p=tr[ts[i]]
        for k in range(i,len(ts)-1):
            p=sp.compose(p,inc[k]); out[ts[k+1]]=p
        break
    # chain from i to j
    chain=[tr[ts[i]]]
    for k in range(i,j):
        chain.append(sp.compose(chain[-1],inc[k]))
    end=tr[ts[j]]; err=np.array([end[0]-chain[-1][0], end[1]-chain[-1][1], sp.wrap(end[2]-chain[-1][2])])
    n=j-i
    for k in range(1,n):
        f=k/n; c=chain[k]; out[ts[i+k]]=(c[0]+f*err[0], c[1]+f*err[1], sp.wrap(c[2]+f*err[2]))
    i=j
with open(outp,'w') as f:
    for t in sorted(out):
        x,y,th=out[t]; f.write("%.6f %.6f %.6f 0 0 0 %.9f %.9f\n"%(t,x,y,math.sin(th/2),math.cos(th/2)))
