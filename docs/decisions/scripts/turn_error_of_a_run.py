"""How far a CARMEN log's odometry misjudges turns, measured against a
SLAM run's trajectory (decision 0016): the log's odometry and the run's
poses are cut into intervals of 0.5 rad of odometry turning, and for each
with a net turn of at least 0.3 rad the error of the odometry's turn, as
a share of it, is (estimated turn - odometry turn) / |odometry turn|.

Usage: python3 turn_error_of_a_run.py LOG.clf RUN/trajectory.tum
"""
import sys, math, bisect
def wrap(a): return (a+math.pi)%(2*math.pi)-math.pi
def odo_of(clf):
    o={}
    for l in open(clf):
        r=l.split()
        if not r or r[0] not in ('FLASER','ROBOTLASER1'): continue
        if r[0]=='FLASER':
            n=int(r[1]); th=float(r[2+n+5]); ts=r[2+n+6]
        else: continue
        o[ts]=th
    return o
def traj(f):
    T=[]
    for l in open(f):
        if l.startswith('#'): continue
        r=l.split(); T.append((r[0],2*math.atan2(float(r[6]),float(r[7]))))
    return T
clf,tum=sys.argv[1],sys.argv[2]
O=odo_of(clf); T=traj(tum)
# stamps in TUM are printed with 6 decimals; match by float
Of={round(float(k),3):v for k,v in O.items()}
pairs=[(th,Of.get(round(float(ts),3))) for ts,th in T]
pairs=[p for p in pairs if p[1] is not None]
# walk and cut intervals whenever odometry turned >= 0.5 rad (accumulated |dθ|) 
errs=[]; acc=0; start=pairs[0]; prev=pairs[0]; signed=0
for p in pairs[1:]:
    d=wrap(p[1]-prev[1]); acc+=abs(d); prev=p
    if acc>=0.5:
        dodo=wrap(p[1]-start[1]); dest=wrap(p[0]-start[0])
        if abs(dodo)>0.3: errs.append((dest-dodo)/abs(dodo))
        start=p; acc=0
errs.sort(); n=len(errs)
rms=math.sqrt(sum(e*e for e in errs)/n)
print('%s: %d turns of >=0.3 rad net; turn error/turn: median %.3f, rms %.3f, p10 %.3f, p90 %.3f, max |.| %.3f'%(clf.split('/')[-1],n,errs[n//2],rms,errs[n//10],errs[9*n//10],max(abs(e) for e in errs)))
