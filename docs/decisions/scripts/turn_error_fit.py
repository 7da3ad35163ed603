"""How far a CARMEN log's odometry misjudges turns and driving, the model
of squall_core::motion::TurnErrorEstimate fitted offline (decision 0016):
the log is cut into the filter's update intervals (1 m driven or 0.5 rad
turned by the odometry), and for each, r = the trajectory's heading change
minus the odometry's, t = the odometry's absolute turning, d = the
distance driven. Prints sqrt of the least-squares rates of
r^2 = a t^2 + b d^2, the same with a constant term, and the lag-one
covariance of r (minus the matcher noise's variance, if white).

Usage: python3 turn_error_fit.py LOG.clf TRAJECTORY.tum
(TRAJECTORY: a run's trajectory.tum, or a simulated world's
ground_truth.tum for the robot's true values)
"""
import sys, math
import numpy as np
def wrap(a): return (a+math.pi)%(2*math.pi)-math.pi
def odo(clf):
    o={}
    for l in open(clf):
        r=l.split()
        if not r or r[0]!='FLASER': continue
        n=int(r[1]); x,y,th=map(float,r[2+n+3:2+n+6]); ts=float(r[2+n+6])
        o[round(ts,3)]=(x,y,th)
    return o
def traj(f):
    T=[]
    for l in open(f):
        if l.startswith('#') or not l.strip(): continue
        r=l.split(); T.append((round(float(r[0]),3),float(r[1]),float(r[2]),2*math.atan2(float(r[6]),float(r[7]))))
    return T
O=odo(sys.argv[1]); T=traj(sys.argv[2])
P=[(O[t[0]],t) for t in T if t[0] in O]
rows=[]; acc_t=0; acc_d=0; s=P[0]; prev=P[0]
for p in P[1:]:
    (ox,oy,oth),_=p; (px,py,pth),_=prev
    acc_t+=abs(wrap(oth-pth)); acc_d+=math.hypot(ox-px,oy-py); prev=p
    if acc_d>=1.0 or acc_t>=0.5:
        r=wrap((p[1][3]-s[1][3])-(p[0][2]-s[0][2]))
        rows.append((acc_t,acc_d,r)); s=p; acc_t=0; acc_d=0
R=np.array(rows); t,d,r=R[:,0],R[:,1],R[:,2]
A=np.c_[t**2,d**2]; sol=np.linalg.lstsq(A,r**2,rcond=None)[0]
A3=np.c_[t**2,d**2,np.ones_like(t)]; sol3=np.linalg.lstsq(A3,r**2,rcond=None)[0]
lag=np.mean(r[1:]*r[:-1])
f=lambda v: math.copysign(math.sqrt(abs(v)),v)
print(f"n={len(r)} a={f(sol[0]):.4f} b={f(sol[1]):.4f} | with c: a={f(sol3[0]):.4f} b={f(sol3[1]):.4f} c={f(sol3[2]):.4f} | lag1 cov={lag:.2e} (σ={f(-lag):.4f})  mean r(d-intervals)={np.mean(r[t<0.2]):.4f}")
