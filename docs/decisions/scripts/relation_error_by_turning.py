"""Where a run's local error comes from (decision 0016): each relation
under 10 s of a CARMEN log's relations file is scored for the run's
trajectory and for the log's raw odometry (translational error of the
relative pose, the heading of the relation's start frame), and the
relations are classed by how much the odometry turned within them
(over 1 rad, 0.3-1 rad, less: "straight"). Also prints percentiles and
the relations where the run is worst.

Usage: python3 relation_error_by_turning.py LOG.relations RUN/trajectory.tum LOG.clf
"""
import sys, math, numpy as np, collections
def wrap(a): return (a+math.pi)%(2*math.pi)-math.pi
def tum(f):
    d={}
    for l in open(f):
        if l.startswith('#') or not l.strip(): continue
        r=l.split(); d[round(float(r[0]),3)]=(float(r[1]),float(r[2]),2*math.atan2(float(r[6]),float(r[7])))
    return d
def odo(clf):
    d={}
    for l in open(clf):
        r=l.split()
        if not r or r[0]!='FLASER': continue
        n=int(r[1]); x,y,th=map(float,r[2+n+3:2+n+6]); d[round(float(r[2+n+6]),3)]=(x,y,th)
    return d
def rel(a,b):
    dx,dy=b[0]-a[0],b[1]-a[1]; c,s=math.cos(a[2]),math.sin(a[2])
    return (c*dx+s*dy,-s*dx+c*dy,wrap(b[2]-a[2]))
def err(e,g):
    return math.hypot(e[0]-g[0],e[1]-g[1])  # approx
rels=[l.split() for l in open(sys.argv[1])]
T=tum(sys.argv[2]); O=odo(sys.argv[3]); G=tum(sys.argv[4]) if len(sys.argv)>4 else None
out=[]
for r in rels:
    t1,t2=round(float(r[0]),3),round(float(r[1]),3)
    if t1 not in T or t2 not in T or t1 not in O or t2 not in O: continue
    g=(float(r[2]),float(r[3]),float(r[7]))
    es=err(rel(T[t1],T[t2]),g); eo=err(rel(O[t1],O[t2]),g)
    out.append((t1,t2,es,eo,T[t1]))
A=np.array([(o[0],o[1],o[2],o[3],o[4][0],o[4][1]) for o in out])
short=A[(A[:,1]-A[:,0])<10]
print('n',len(A),'short',len(short),'slam %.4f odo %.4f'%(short[:,2].mean(),short[:,3].mean()))
# by time bins
for q in [50,75,90,99]: print('pct',q,'slam %.4f odo %.4f'%(np.percentile(short[:,2],q),np.percentile(short[:,3],q)))
worse=short[short[:,2]>short[:,3]]
print('share slam>odo %.2f'%(len(worse)/len(short)))
# spatial: where are the worst
idx=np.argsort(-short[:,2])[:15]
for i in idx: print('t %.1f-%.1f slam %.3f odo %.3f at (%.1f,%.1f)'%tuple(short[i]))
# classify by rotation within relation
Ol=sorted(O.items())
import bisect
ts=[t for t,_ in Ol]
def turned(t1,t2):
    i=bisect.bisect_left(ts,t1); j=bisect.bisect_right(ts,t2)
    s=0;dd=0
    for k in range(i+1,j):
        s+=abs(wrap(Ol[k][1][2]-Ol[k-1][1][2])); dd+=math.hypot(Ol[k][1][0]-Ol[k-1][1][0],Ol[k][1][1]-Ol[k-1][1][1])
    return s,dd
cls=collections.defaultdict(list) if False else {}
for o in out:
    if o[1]-o[0]>=10: continue
    s,dd=turned(o[0],o[1])
    key='turning>1rad' if s>1 else ('turning 0.3-1' if s>0.3 else 'straight')
    cls.setdefault(key,[]).append((o[2],o[3]))
for k,v in cls.items():
    v=np.array(v); print(k,len(v),'slam %.4f odo %.4f'%(v[:,0].mean(),v[:,1].mean()))
